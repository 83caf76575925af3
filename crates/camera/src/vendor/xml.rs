//! A small XML scan for the vendor files: the text of every leaf element with the names of the
//! elements around it. Enough for DIMAP and GDAL metadata (no namespaces, entities beyond the
//! five predefined ones, or mixed content are needed there), and it never panics.

/// An element without child elements.
pub(super) struct Leaf {
    /// The enclosing elements, outermost first, each with a number unique in the document so
    /// that siblings of one parent can be told from those of another of the same name.
    pub ancestors: Vec<(String, usize)>,
    pub name: String,
    /// The `name="…"` attribute, when there is one.
    pub name_attr: Option<String>,
    pub text: String,
}

impl Leaf {
    pub fn parent(&self) -> Option<&str> {
        self.ancestors.last().map(|(n, _)| n.as_str())
    }

    pub fn within(&self, name: &str) -> Option<usize> {
        self.ancestors
            .iter()
            .rev()
            .find(|(n, _)| n == name)
            .map(|(_, id)| *id)
    }
}

/// The leaves of `text` in document order, or what is wrong with it (unclosed or mismatched
/// elements, a truncated tag).
pub(super) fn leaves(text: &str) -> Result<Vec<Leaf>, String> {
    let mut out = Vec::new();
    // Open elements: name, id, name attribute, whether a child element was seen, text start.
    let mut stack: Vec<(String, usize, Option<String>, bool, usize)> = Vec::new();
    let mut next_id = 0;
    let mut pos = 0;
    while let Some(lt) = text[pos..].find('<').map(|i| pos + i) {
        let rest = &text[lt..];
        if rest.starts_with("<!--") {
            pos = lt + rest.find("-->").ok_or("unterminated comment")? + 3;
            continue;
        }
        if rest.starts_with("<![CDATA[") {
            pos = lt + rest.find("]]>").ok_or("unterminated CDATA section")? + 3;
            continue;
        }
        let gt = lt + rest.find('>').ok_or("truncated tag")?;
        let tag = &text[lt + 1..gt];
        pos = gt + 1;
        if tag.starts_with('?') || tag.starts_with('!') {
            continue;
        }
        if let Some(name) = tag.strip_prefix('/') {
            let name = local(name.trim());
            let (open, _, attr, has_child, start) = stack
                .pop()
                .ok_or_else(|| format!("</{name}> closes nothing"))?;
            if open != name {
                return Err(format!("<{open}> closed by </{name}>"));
            }
            if !has_child {
                out.push(Leaf {
                    ancestors: stack.iter().map(|s| (s.0.clone(), s.1)).collect(),
                    name: open,
                    name_attr: attr,
                    text: unescape(text[start..lt].trim()),
                });
            }
            continue;
        }
        let self_closing = tag.ends_with('/');
        let tag = tag.trim_end_matches('/');
        let name_end = tag.find(|c: char| c.is_whitespace()).unwrap_or(tag.len());
        let name = local(&tag[..name_end]);
        if name.is_empty() {
            return Err("an element without a name".into());
        }
        let attr = name_attribute(&tag[name_end..]);
        if let Some(parent) = stack.last_mut() {
            parent.3 = true;
        }
        next_id += 1;
        if self_closing {
            out.push(Leaf {
                ancestors: stack.iter().map(|s| (s.0.clone(), s.1)).collect(),
                name,
                name_attr: attr,
                text: String::new(),
            });
        } else {
            stack.push((name, next_id, attr, false, pos));
        }
    }
    if let Some((open, ..)) = stack.last() {
        return Err(format!("truncated: <{open}> is never closed"));
    }
    Ok(out)
}

/// The name without a namespace prefix.
fn local(name: &str) -> String {
    name.rsplit(':').next().unwrap_or(name).to_string()
}

/// The value of a `name="…"` (or `'…'`) attribute.
fn name_attribute(attrs: &str) -> Option<String> {
    let mut rest = attrs;
    while let Some(i) = rest.find("name") {
        let before = rest[..i].chars().next_back();
        let after = rest[i + 4..].trim_start();
        rest = &rest[i + 4..];
        if before.is_some_and(|c| !c.is_whitespace()) {
            continue;
        }
        let Some(after) = after.strip_prefix('=') else {
            continue;
        };
        let after = after.trim_start();
        let quote = after.chars().next()?;
        if quote != '"' && quote != '\'' {
            return None;
        }
        let body = &after[1..];
        let end = body.find(quote)?;
        return Some(unescape(&body[..end]));
    }
    None
}

fn unescape(s: &str) -> String {
    if !s.contains('&') {
        return s.to_string();
    }
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&amp;", "&")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scan() {
        let l = leaves(
            "<?xml version=\"1.0\"?>\n<!-- c --><A><B><C>1</C><C>2</C></B><D x='1' name=\"n&amp;m\">t</D><E/></A>",
        )
        .unwrap();
        let names: Vec<_> = l
            .iter()
            .map(|l| (l.name.as_str(), l.text.as_str()))
            .collect();
        assert_eq!(names, [("C", "1"), ("C", "2"), ("D", "t"), ("E", "")]);
        assert_eq!(l[0].parent(), Some("B"));
        assert_eq!(l[2].name_attr.as_deref(), Some("n&m"));
        assert_eq!(l[0].within("B"), l[1].within("B"));
        for bad in ["<A><B>1</A>", "<A>", "<A><B", "</A>", "<A><!-- x"] {
            assert!(leaves(bad).is_err(), "{bad}");
        }
    }
}
