//! The Gemini `generateContent` wire format, as the release uses it: one user turn holding the
//! prompt text and the input image (inline base64 PNG), `responseModalities: ["IMAGE"]`, a low
//! temperature and an image config; the answer's first inline image part is the result.

use base64::Engine;
use serde_json::{json, Value};

/// The JSON body of a request.
pub(crate) fn request_body(prompt: &str, png: &[u8], generation_config: &Value) -> Value {
    json!({
        "contents": [{
            "role": "user",
            "parts": [
                { "text": prompt },
                { "inline_data": {
                    "mime_type": "image/png",
                    "data": base64::engine::general_purpose::STANDARD.encode(png),
                } },
            ],
        }],
        "generationConfig": generation_config,
    })
}

/// Supported output aspect ratios of the image models.
const ASPECT_RATIOS: [(u32, u32); 10] = [
    (1, 1),
    (2, 3),
    (3, 2),
    (3, 4),
    (4, 3),
    (4, 5),
    (5, 4),
    (9, 16),
    (16, 9),
    (21, 9),
];

/// The supported aspect ratio closest (in log ratio) to a `width × height` image.
pub(crate) fn nearest_aspect_ratio(width: usize, height: usize) -> String {
    let r = (width as f64 / height.max(1) as f64).ln();
    let (a, b) = ASPECT_RATIOS
        .iter()
        .min_by(|x, y| {
            let dx = ((x.0 as f64 / x.1 as f64).ln() - r).abs();
            let dy = ((y.0 as f64 / y.1 as f64).ln() - r).abs();
            dx.total_cmp(&dy)
        })
        .copied()
        .unwrap_or((1, 1));
    format!("{a}:{b}")
}

/// The first inline image of a response: (MIME type, decoded bytes), or a message saying why
/// there is none (block reason, finish reason, the model's text).
pub(crate) fn extract_image(body: &[u8]) -> Result<(String, Vec<u8>), String> {
    let value: Value = serde_json::from_slice(body).map_err(|e| {
        let head = String::from_utf8_lossy(&body[..body.len().min(120)]).into_owned();
        format!("not JSON ({e}); body starts with {head:?}")
    })?;
    let candidates = value
        .get("candidates")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    let mut texts = Vec::new();
    let mut finish = Vec::new();
    for cand in &candidates {
        if let Some(reason) = cand.get("finishReason").and_then(Value::as_str) {
            finish.push(reason.to_string());
        }
        let parts = cand
            .pointer("/content/parts")
            .and_then(Value::as_array)
            .cloned()
            .unwrap_or_default();
        for part in &parts {
            if let Some(t) = part.get("text").and_then(Value::as_str) {
                texts.push(t.to_string());
            }
            let Some(inline) = part.get("inlineData").or_else(|| part.get("inline_data")) else {
                continue;
            };
            let mime = inline
                .get("mimeType")
                .or_else(|| inline.get("mime_type"))
                .and_then(Value::as_str)
                .unwrap_or("");
            if !mime.starts_with("image/") {
                continue;
            }
            let data = inline
                .get("data")
                .and_then(Value::as_str)
                .ok_or("an inline image part has no base64 `data`")?;
            let bytes = base64::engine::general_purpose::STANDARD
                .decode(data.trim())
                .map_err(|e| format!("the inline image is not valid base64: {e}"))?;
            return Ok((mime.to_string(), bytes));
        }
    }
    let mut why = Vec::new();
    if let Some(block) = value
        .pointer("/promptFeedback/blockReason")
        .and_then(Value::as_str)
    {
        why.push(format!("prompt blocked ({block})"));
    }
    if candidates.is_empty() {
        why.push("no candidates".into());
    }
    if !finish.is_empty() {
        why.push(format!("finish reason {}", finish.join(", ")));
    }
    if !texts.is_empty() {
        let text: String = texts.join(" ").chars().take(300).collect();
        why.push(format!("the model answered with text: {text:?}"));
    }
    Err(format!("no image in the response ({})", why.join("; ")))
}

/// The `error.message` of an error body, else its first characters.
pub(crate) fn error_message(body: &[u8]) -> String {
    serde_json::from_slice::<Value>(body)
        .ok()
        .and_then(|v| {
            v.pointer("/error/message")
                .and_then(Value::as_str)
                .map(str::to_string)
        })
        .unwrap_or_else(|| String::from_utf8_lossy(body).chars().take(300).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn request_carries_prompt_image_and_config() {
        let cfg = json!({"responseModalities": ["IMAGE"], "temperature": 0.2});
        let body = request_body("make it winter", &[1, 2, 3], &cfg);
        assert_eq!(
            body.pointer("/contents/0/parts/0/text").unwrap(),
            "make it winter"
        );
        assert_eq!(
            body.pointer("/contents/0/parts/1/inline_data/mime_type")
                .unwrap(),
            "image/png"
        );
        assert_eq!(
            body.pointer("/contents/0/parts/1/inline_data/data")
                .unwrap(),
            "AQID"
        );
        assert_eq!(
            body.pointer("/generationConfig/responseModalities/0")
                .unwrap(),
            "IMAGE"
        );
    }

    #[test]
    fn images_are_found_in_either_spelling_and_absence_is_explained() {
        let camel = br#"{"candidates":[{"content":{"parts":[{"text":"here"},{"inlineData":{"mimeType":"image/png","data":"AQID"}}]}}]}"#;
        assert_eq!(
            extract_image(camel).unwrap(),
            ("image/png".into(), vec![1, 2, 3])
        );
        let snake = br#"{"candidates":[{"content":{"parts":[{"inline_data":{"mime_type":"image/jpeg","data":"AQID"}}]}}]}"#;
        assert_eq!(extract_image(snake).unwrap().0, "image/jpeg");
        let refused = br#"{"candidates":[{"finishReason":"IMAGE_SAFETY","content":{"parts":[{"text":"I cannot"}]}}]}"#;
        let err = extract_image(refused).unwrap_err();
        assert!(
            err.contains("IMAGE_SAFETY") && err.contains("I cannot"),
            "{err}"
        );
        assert!(extract_image(b"<html>").unwrap_err().contains("not JSON"));
        assert_eq!(nearest_aspect_ratio(1024, 1024), "1:1");
        assert_eq!(nearest_aspect_ratio(1600, 900), "16:9");
    }
}
