//! Text the layers share: quoting what a user sent back to them in a message (a value can be
//! megabytes long, and an error must not echo it whole), and the clock as a program names it.

/// The characters of a value an error message quotes at most.
pub const QUOTED: usize = 80;

/// `s` quoted and escaped as `{:?}` does, cut to its first [`QUOTED`] characters with its length
/// told when longer.
pub fn quote(s: &str) -> String {
    match s.char_indices().nth(QUOTED) {
        None => format!("{s:?}"),
        Some((end, _)) => format!("{:?}… ({} bytes)", &s[..end], s.len()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_values_are_quoted_whole_and_long_ones_cut() {
        assert_eq!(quote("fanuc"), "\"fanuc\"");
        let long = "é".repeat(1000);
        let q = quote(&long);
        assert!(q.starts_with(&format!("\"{}\"…", "é".repeat(QUOTED))), "{q}");
        assert!(q.ends_with("(2000 bytes)"), "{q}");
    }
}

/// `YYYY-MM-DD HH:MM` of the system clock, UTC (civil-from-days, no calendar crate needed).
pub fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + (m <= 2) as i64;
    format!("{y:04}-{m:02}-{d:02} {:02}:{:02}", rem / 3600, rem % 3600 / 60)
}
