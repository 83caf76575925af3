//! Shell words: quoting arguments into a script or a message a user can paste, splitting a
//! user's `--sbatch-args`.

use anyhow::{bail, Result};

/// `word` as one POSIX shell word: unchanged when it is made of safe characters, else in single
/// quotes (a quote inside written `'\''`).
pub fn quote(word: &str) -> String {
    let safe = |c: char| c.is_ascii_alphanumeric() || "-_./=:,@%+".contains(c);
    if !word.is_empty() && word.chars().all(safe) {
        return word.to_string();
    }
    format!("'{}'", word.replace('\'', r"'\''"))
}

/// Words joined by spaces, each quoted.
pub fn join(words: &[String]) -> String {
    words.iter().map(|w| quote(w)).collect::<Vec<_>>().join(" ")
}

/// Splits `text` into words as a POSIX shell does (single and double quotes, backslashes), without
/// expansions.
pub fn split(text: &str) -> Result<Vec<String>> {
    let (mut words, mut word, mut in_word) = (Vec::new(), String::new(), false);
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        match c {
            c if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut word));
                }
                in_word = false;
                continue;
            }
            '\'' => word.extend(chars.by_ref().take_while(|&c| c != '\'')),
            '"' => loop {
                match chars.next() {
                    Some('"') => break,
                    Some('\\') => word.extend(chars.next()),
                    Some(c) => word.push(c),
                    None => bail!("unbalanced double quote in {text:?}"),
                }
            },
            '\\' => word.extend(chars.next()),
            c => word.push(c),
        }
        in_word = true;
    }
    if in_word {
        words.push(word);
    }
    Ok(words)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoted_words_split_back_to_themselves() {
        let words: Vec<String> = ["plain", "a b", "it's", "", "$HOME", "--x=1"]
            .map(String::from)
            .to_vec();
        assert_eq!(split(&join(&words)).unwrap(), words);
        assert_eq!(quote("a/b.tif"), "a/b.tif");
        assert_eq!(quote("a b"), "'a b'");
        assert_eq!(
            split(r#"-p gpu --gres="gpu:1" --comment 'x y'"#).unwrap(),
            ["-p", "gpu", "--gres=gpu:1", "--comment", "x y"]
        );
    }
}
