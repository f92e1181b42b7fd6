//! PLACEHOLDER until the rapid branch lands.
use std::path::Path;
pub fn rapidchecker_available() -> bool {
    std::process::Command::new("rapidchecker")
        .arg("--help")
        .output()
        .is_ok()
}
pub fn rapidcheck(path: &Path) -> Result<(), String> {
    let out = std::process::Command::new("rapidchecker")
        .arg(path)
        .output()
        .map_err(|e| e.to_string())?;
    if out.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&out.stdout).into_owned())
    }
}
