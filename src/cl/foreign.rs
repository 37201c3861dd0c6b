//! What a statement that is no CL record looks like: NC sent where CL was meant (an NC program
//! uploaded instead of its CL) reads as nothing but unknown records, and an empty program that
//! ends well is easily taken for a posted part. The post refuses such input by what is found
//! here.

/// The kind of NC a statement reads as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NcKind {
    /// Word address: `N10 G1 F500`, `G0X0Y0`, `/M1`, Siemens `X=10`.
    WordAddress,
    /// Heidenhain conversational: `5 L X+10 R0 FMAX`, `BEGIN PGM 1 MM`.
    Conversational,
}

impl NcKind {
    pub fn name(self) -> &'static str {
        match self {
            NcKind::WordAddress => "G-code",
            NcKind::Conversational => "Heidenhain conversational NC",
        }
    }
}

/// The first NC-looking statement and how many there were.
#[derive(Clone, Debug, Default)]
pub struct NcSeen {
    pub blocks: u32,
    pub first: Option<(NcKind, u32, String)>,
}

impl NcSeen {
    pub(super) fn note(&mut self, stmt: &str, line: u32) {
        if let Some(kind) = nc_kind(stmt) {
            self.blocks += 1;
            self.first.get_or_insert_with(|| (kind, line, stmt.trim().to_string()));
        }
    }
}

/// The NC kind a statement reads as, if any. A comment or a tape frame line alone (`%`,
/// `(TEXT)`) is none: it says nothing either way.
pub fn nc_kind(stmt: &str) -> Option<NcKind> {
    let s = stmt.trim();
    if conversational(s) {
        return Some(NcKind::Conversational);
    }
    word_address(s).then_some(NcKind::WordAddress)
}

/// Letter–number words only (at least one), `(…)` and `;…` comments and a block delete aside.
fn word_address(s: &str) -> bool {
    let code = s.split(';').next().unwrap_or("");
    let mut b = code.trim_start().trim_start_matches('/').bytes().peekable();
    let mut words = 0;
    loop {
        match b.peek() {
            None => return words > 0,
            Some(c) if c.is_ascii_whitespace() => {
                b.next();
            }
            Some(b'(') => {
                // A comment to its closing parenthesis (or the end of the block).
                for c in b.by_ref() {
                    if c == b')' {
                        break;
                    }
                }
            }
            Some(c) if c.is_ascii_alphabetic() => {
                b.next();
                if b.peek() == Some(&b'=') {
                    b.next();
                }
                if matches!(b.peek(), Some(b'+' | b'-')) {
                    b.next();
                }
                let mut digits = 0;
                while let Some(c) = b.peek().filter(|c| c.is_ascii_digit() || **c == b'.') {
                    digits += usize::from(c.is_ascii_digit());
                    b.next();
                }
                if digits == 0 {
                    return false;
                }
                words += 1;
            }
            Some(_) => return false,
        }
    }
}

/// A Heidenhain block: an optional block number, then a conversational word.
fn conversational(s: &str) -> bool {
    let rest = s.trim_start_matches(|c: char| c.is_ascii_digit()).trim_start();
    let w: Vec<&str> = rest.split_whitespace().take(2).collect();
    match w.as_slice() {
        ["BEGIN" | "END", "PGM"] | ["TOOL", "CALL"] | ["CYCL", "DEF" | "CALL"] | ["BLK", "FORM"] => true,
        // A straight line or arc with an axis word after it (`L X+10`, `C X+5 Y+0 DR-`).
        ["L" | "C" | "CC" | "LP" | "CP", axis] => {
            let a = axis.as_bytes();
            a.len() >= 2 && b"XYZABCIJKPR".contains(&a[0]) && matches!(a[1], b'+' | b'-' | b'0'..=b'9')
        }
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nc_is_told_from_cl_and_from_text() {
        for s in [
            "G0 X1 Y2 Z3",
            "N10 G01 X-1.5 F500",
            "G0X0Y0",
            "/M1",
            "O1000",
            "X=10 Y=-2.5",
            "G1 X1 (CUT) Y2 ; end",
        ] {
            assert_eq!(nc_kind(s), Some(NcKind::WordAddress), "{s}");
        }
        for s in [
            "0 BEGIN PGM 1 MM",
            "5 L X+10 R0 FMAX",
            "TOOL CALL 1 Z S5000",
            "7 CYCL DEF 200 BOHREN",
        ] {
            assert_eq!(nc_kind(s), Some(NcKind::Conversational), "{s}");
        }
        for s in [
            "%",
            "(PROGRAM 1)",
            "",
            "GOTO/1,2,3",
            "FROBNICATE",
            "\u{1}\u{2}PNG",
            "hello world",
            "G",
            "TOOL PATH/X",
        ] {
            assert_eq!(nc_kind(s), None, "{s}");
        }
    }
}
