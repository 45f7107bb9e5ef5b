//! Consistent Overhead Byte Stuffing (Cheshire and Baker, IEEE/ACM ToN 1999):
//! removes every 0x00 from a frame, so that 0x00 delimits frames.

/// Largest COBS encoding of `n` bytes (without the delimiter).
pub const fn cobs_max_len(n: usize) -> usize {
    n + n / 254 + 1
}

/// COBS-encodes `src` into `dst` (no delimiter); returns the length, or
/// `None` if `dst` is shorter than [`cobs_max_len`]`(src.len())`.
pub fn cobs_encode(src: &[u8], dst: &mut [u8]) -> Option<usize> {
    if dst.len() < cobs_max_len(src.len()) {
        return None;
    }
    let mut code_at = 0;
    let mut out = 1;
    let mut code = 1u8;
    for &b in src {
        if b == 0 {
            dst[code_at] = code;
            code_at = out;
            out += 1;
            code = 1;
        } else {
            dst[out] = b;
            out += 1;
            code += 1;
            if code == 0xFF {
                dst[code_at] = code;
                code_at = out;
                out += 1;
                code = 1;
            }
        }
    }
    dst[code_at] = code;
    Some(out)
}

/// Decodes COBS data (no delimiter) in place; returns the decoded length, or
/// `None` if a zero byte appears or a group runs past the end.
pub fn cobs_decode_in_place(buf: &mut [u8]) -> Option<usize> {
    let mut i = 0;
    let mut out = 0;
    while i < buf.len() {
        let code = buf[i];
        if code == 0 {
            return None;
        }
        i += 1;
        let run = code as usize - 1;
        let block = buf.get(i..i + run)?;
        if block.contains(&0) {
            return None;
        }
        // out < i always (the code bytes are never copied): a move to the left
        buf.copy_within(i..i + run, out);
        out += run;
        i += run;
        if code != 0xFF && i < buf.len() {
            buf[out] = 0;
            out += 1;
        }
    }
    Some(out)
}

/// [`cobs_decode_in_place`] of a buffer known to hold no zero byte (the
/// [`Decoder`](super::Decoder) splits the stream at every 0x00): no zero
/// checks, short runs (the usual case: a zero residual every few bytes) moved
/// bytewise, long runs with one block move.
pub(super) fn cobs_decode_nonzero(buf: &mut [u8]) -> Option<usize> {
    let mut i = 0;
    let mut out = 0;
    while i < buf.len() {
        let code = buf[i];
        i += 1;
        let run = (code as usize).wrapping_sub(1);
        let end = i.checked_add(run).filter(|&e| e <= buf.len())?;
        if run <= 16 {
            for j in i..end {
                // out < j always: the code byte is never copied
                buf[out] = buf[j];
                out += 1;
            }
        } else {
            buf.copy_within(i..end, out);
            out += run;
        }
        i = end;
        if code != 0xFF && i < buf.len() {
            buf[out] = 0;
            out += 1;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    #[test]
    fn cobs_round_trips_zero_runs_and_long_blocks() {
        let mut rng = SplitMix64::new(3);
        for len in [0usize, 1, 2, 253, 254, 255, 256, 508, 509, 1000] {
            for zeros in [0u64, 2, 10] {
                let src: Vec<u8> = (0..len)
                    .map(|_| {
                        if zeros > 0 && rng.next_u64().is_multiple_of(zeros) {
                            0
                        } else {
                            (rng.next_u64() % 255 + 1) as u8
                        }
                    })
                    .collect();
                let mut enc = vec![0u8; cobs_max_len(len)];
                let n = cobs_encode(&src, &mut enc).unwrap();
                assert!(enc[..n].iter().all(|&b| b != 0));
                let mut buf = enc[..n].to_vec();
                let m = cobs_decode_in_place(&mut buf).unwrap();
                assert_eq!(&buf[..m], &src[..], "len {len} zeros {zeros}");
            }
        }
        assert_eq!(cobs_decode_in_place(&mut [3, 1]), None);
        assert_eq!(cobs_decode_in_place(&mut [2, 0]), None);
    }
}
