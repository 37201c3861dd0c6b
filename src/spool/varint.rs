//! LEB128 integers and zigzag signs: what the job stores (block store, line map) are written in.

/// Small magnitudes of either sign to small unsigned numbers: 0, −1, 1, −2 … → 0, 1, 2, 3 ….
pub(super) fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

pub(super) fn unzigzag(v: u64) -> i64 {
    ((v >> 1) as i64) ^ -((v & 1) as i64)
}

/// Reads one [`put_varint`] wrote, a byte at a time from `byte`; `too_long`: the error of one
/// that runs past 64 bits.
pub(super) fn get_varint(
    mut byte: impl FnMut() -> std::io::Result<u8>,
    too_long: impl FnOnce() -> std::io::Error,
) -> std::io::Result<u64> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let b = byte()?;
        v |= ((b & 0x7f) as u64) << shift;
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(too_long())
}

/// Seven bits a byte, low first; the high bit says another follows.
pub(super) fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push(v as u8 | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}
