//! Numbers in names (job ids, frame files, sample log files) read back
//! only in the one spelling the crate writes them: `str::parse` also
//! takes `+1` and `01`, and two spellings of one number would give one
//! job, frame or log two names.

/// `s` as a number if `s` is exactly how `n.to_string()` writes it (no
/// sign, no leading zero).
pub fn parse_canonical_u64(s: &str) -> Option<u64> {
    let n: u64 = s.parse().ok()?;
    (n.to_string() == s).then_some(n)
}

/// `s` as a number if `s` is exactly how `format!("{n:0width$}")` writes
/// it: zero-padded to `width` digits, no leading zero beyond them.
pub fn parse_padded_u64(s: &str, width: usize) -> Option<u64> {
    let n: u64 = s.parse().ok()?;
    (format!("{n:0width$}") == s).then_some(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_written_spelling_parses() {
        assert_eq!(parse_canonical_u64("0"), Some(0));
        assert_eq!(parse_canonical_u64("42"), Some(42));
        assert_eq!(parse_canonical_u64(&u64::MAX.to_string()), Some(u64::MAX));
        for bad in [
            "",
            "+1",
            "-1",
            "01",
            "00",
            " 1",
            "1 ",
            "1e3",
            "18446744073709551616",
        ] {
            assert_eq!(parse_canonical_u64(bad), None, "{bad:?}");
        }
        assert_eq!(parse_padded_u64("0007", 4), Some(7));
        assert_eq!(parse_padded_u64("12345", 4), Some(12345));
        for bad in ["7", "007", "00007", "+007", "012345"] {
            assert_eq!(parse_padded_u64(bad, 4), None, "{bad:?}");
        }
    }
}
