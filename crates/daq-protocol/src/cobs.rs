//! Consistent overhead byte stuffing (Cheshire & Baker, 1999): removes every zero byte from a
//! body at a cost of one byte per 254, so that `00` can delimit frames.

/// Longest COBS encoding of `n` bytes: `n + ⌊n/254⌋ + 1`.
pub const fn cobs_max_encoded_len(n: usize) -> usize {
    n + n / 254 + 1
}

/// Encodes `data` into `out` (at least [`cobs_max_encoded_len`] bytes; the caller checks) and
/// returns the length written. The output holds no zero byte.
pub fn cobs_encode(data: &[u8], out: &mut [u8]) -> usize {
    let mut code_at = 0;
    let mut code = 1u8;
    let mut w = 1;
    for &b in data {
        if b == 0 {
            out[code_at] = code;
            code_at = w;
            w += 1;
            code = 1;
        } else {
            out[w] = b;
            w += 1;
            code += 1;
            if code == 0xFF {
                out[code_at] = code;
                code_at = w;
                w += 1;
                code = 1;
            }
        }
    }
    out[code_at] = code;
    w
}

/// Decodes a COBS block (without its `00` delimiter) in place; returns the decoded length, or
/// `None` if a code byte is zero or points past the end.
pub fn cobs_decode_in_place(buf: &mut [u8]) -> Option<usize> {
    let n = buf.len();
    let (mut r, mut w) = (0, 0);
    while r < n {
        let code = buf[r];
        if code == 0 {
            return None;
        }
        let run = usize::from(code) - 1;
        if r + 1 + run > n {
            return None;
        }
        // Copy the run down (w ≤ r always: the output is never longer than the input).
        buf.copy_within(r + 1..r + 1 + run, w);
        w += run;
        r += 1 + run;
        if code != 0xFF && r < n {
            buf[w] = 0;
            w += 1;
        }
    }
    Some(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip(data: &[u8]) {
        let mut out = [0u8; 1024];
        let n = cobs_encode(data, &mut out);
        assert!(n <= cobs_max_encoded_len(data.len()));
        assert!(!out[..n].contains(&0), "{:?}", &out[..n]);
        let m = cobs_decode_in_place(&mut out[..n]).unwrap();
        assert_eq!(&out[..m], data);
    }

    #[test]
    fn known_encodings_and_roundtrips() {
        // The examples of the COBS paper / Wikipedia.
        let mut out = [0u8; 16];
        let n = cobs_encode(&[0x00], &mut out);
        assert_eq!(&out[..n], &[0x01, 0x01]);
        let n = cobs_encode(&[0x11, 0x22, 0x00, 0x33], &mut out);
        assert_eq!(&out[..n], &[0x03, 0x11, 0x22, 0x02, 0x33]);
        let n = cobs_encode(&[0x11, 0x00, 0x00, 0x00], &mut out);
        assert_eq!(&out[..n], &[0x02, 0x11, 0x01, 0x01, 0x01]);
        roundtrip(&[]);
        let long: [u8; 600] = core::array::from_fn(|i| (i % 255) as u8 + 1);
        roundtrip(&long);
        let zeros = [0u8; 300];
        roundtrip(&zeros);
        let mixed: [u8; 520] = core::array::from_fn(|i| if i % 97 == 0 { 0 } else { i as u8 });
        roundtrip(&mixed);
    }
}
