//! The process's file-mode creation mask, read without changing it.
//!
//! New output files get `0o666 & !umask` like the files of any other program (`cp`, an
//! editor), so a service with `UMask=0002` writes group-writable outputs into a shared project
//! folder (docs/DAEMON-INSTALL.md). `umask(2)` can only be read by setting it, which races with
//! other threads creating files; Linux shows it in `/proc/self/status` (`Umask:`, since 4.7).

/// The umask of this process; `0o022` where it cannot be read.
pub fn get() -> u32 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| parse(&s))
        .unwrap_or(0o022)
}

fn parse(status: &str) -> Option<u32> {
    let line = status.lines().find(|l| l.starts_with("Umask:"))?;
    u32::from_str_radix(line["Umask:".len()..].trim(), 8).ok()
}

/// The mode of a new file: `0o666` less the umask.
pub fn new_file_mode() -> u32 {
    0o666 & !get()
}

#[cfg(test)]
mod tests {
    #[test]
    fn reads_the_umask_line() {
        assert_eq!(
            super::parse("Name:\tx\nUmask:\t0002\nState:\tR\n"),
            Some(0o002)
        );
        assert_eq!(super::parse("Name:\tx\n"), None);
        let m = super::get();
        assert_eq!(m & !0o777, 0, "{m:o}");
    }
}
