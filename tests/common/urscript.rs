//! PLACEHOLDER until the flowrun branch lands.
pub fn check_urscript(text: &str) -> Result<(), String> {
    let mut depth: i64 = 0;
    for l in text.lines() {
        let t = l.trim();
        if t.ends_with(':') && !t.starts_with("else") && !t.starts_with("elif") {
            depth += 1;
        }
        if t == "end" {
            depth -= 1;
        }
        if depth < 0 {
            return Err(format!("unbalanced at {t}"));
        }
    }
    if depth != 0 {
        return Err(format!("{depth} blocks not closed"));
    }
    Ok(())
}
