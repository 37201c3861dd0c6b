//! Quoting what a user sent back to them in a message: a value can be megabytes long (a form
//! field, a query parameter, a JSON string), and an error must not echo it whole.

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
