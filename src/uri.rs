//! Percent-encoding (RFC 3986), as glTF URIs and the API's query strings
//! write it.

/// `s` with every byte outside RFC 3986's unreserved set as `%XX`.
pub fn percent_encode(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for b in s.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// `%XX` escapes decoded; `None` for a malformed escape or bytes that are
/// not UTF-8. A `+` stays a `+` (a query string's space is
/// [`query_decode`]).
pub fn percent_decode(s: &str) -> Option<String> {
    let mut out = Vec::with_capacity(s.len());
    let mut bytes = s.bytes();
    while let Some(b) = bytes.next() {
        if b == b'%' {
            let hex = [bytes.next()?, bytes.next()?];
            out.push(u8::from_str_radix(std::str::from_utf8(&hex).ok()?, 16).ok()?);
        } else {
            out.push(b);
        }
    }
    String::from_utf8(out).ok()
}

/// A query string's value decoded: `+` is a space, as forms send it, and
/// `%2B` a plus.
pub fn query_decode(s: &str) -> Option<String> {
    percent_decode(&s.replace('+', " "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_round_trip_and_malformed_ones_are_refused() {
        let text = "a b+c/ü%";
        assert_eq!(percent_encode(text), "a%20b%2Bc%2F%C3%BC%25");
        assert_eq!(percent_decode(&percent_encode(text)).as_deref(), Some(text));
        assert_eq!(percent_decode("a+b").as_deref(), Some("a+b"));
        assert_eq!(query_decode("a+b%2Bc").as_deref(), Some("a b+c"));
        for bad in ["%", "%4", "%zz", "%FF"] {
            assert_eq!(percent_decode(bad), None, "{bad}");
        }
    }
}
