//! Samples packed at their real bit widths: 10 bits for each ADC channel (voltage, current,
//! speed, in that order) and 12 for the encoder counter, for the channels of the mask, in
//! little-endian bit order — bit 0 of the block is bit 0 of the first channel of the first
//! sample. Four channels take 42 bits, so 32 samples pack into 168 bytes.

/// Channels a sample can carry: voltage, current and speed (10-bit ADC), encoder (12-bit).
pub const CHANNEL_COUNT: usize = 4;
/// Largest ADC code (10 bits).
pub const ADC_MAX: u16 = (1 << 10) - 1;
/// The encoder counter wraps at this count (12 bits).
pub const ENCODER_MODULUS: u16 = 1 << 12;

/// One sample: ADC codes of voltage, current and speed, and the encoder count (channels not in
/// the mask are 0).
pub type Sample = [u16; CHANNEL_COUNT];

/// Width of channel `c` \[bits\].
const fn width(c: usize) -> usize {
    if c == 3 {
        12
    } else {
        10
    }
}

/// Bits one sample of `channels` takes.
pub const fn bits_per_sample(channels: u8) -> usize {
    let mut bits = 0;
    let mut c = 0;
    while c < CHANNEL_COUNT {
        if channels & (1 << c) != 0 {
            bits += width(c);
        }
        c += 1;
    }
    bits
}

/// Bytes `count` samples of `channels` take, packed (the last byte padded with zero bits).
pub const fn packed_len(channels: u8, count: usize) -> usize {
    (bits_per_sample(channels) * count).div_ceil(8)
}

/// Writes sample `i` of a block into `packed` (which must hold `packed_len(channels, i + 1)`
/// bytes, zeroed where not yet written). Values wider than their channel are truncated to it.
pub fn pack_sample(packed: &mut [u8], channels: u8, i: usize, sample: &Sample) {
    let mut bit = i * bits_per_sample(channels);
    for (c, &value) in sample.iter().enumerate() {
        if channels & (1 << c) == 0 {
            continue;
        }
        let w = width(c);
        let v = u32::from(value) & ((1 << w) - 1);
        for b in 0..w {
            if v & (1 << b) != 0 {
                packed[(bit + b) / 8] |= 1 << ((bit + b) % 8);
            }
        }
        bit += w;
    }
}

/// Reads sample `i` of a block packed with `channels`.
pub fn unpack_sample(packed: &[u8], channels: u8, i: usize) -> Sample {
    let mut out = [0u16; CHANNEL_COUNT];
    let mut bit = i * bits_per_sample(channels);
    for (c, slot) in out.iter_mut().enumerate() {
        if channels & (1 << c) == 0 {
            continue;
        }
        let w = width(c);
        let mut v = 0u16;
        for b in 0..w {
            if packed
                .get((bit + b) / 8)
                .is_some_and(|byte| byte & (1 << ((bit + b) % 8)) != 0)
            {
                v |= 1 << b;
            }
        }
        *slot = v;
        bit += w;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widths_and_roundtrip() {
        assert_eq!(bits_per_sample(0b1111), 42);
        assert_eq!(packed_len(0b1111, 32), 168);
        assert_eq!(bits_per_sample(0b0010), 10);
        for channels in 1..=0b1111u8 {
            let mut packed = [0u8; 168];
            let samples: [Sample; 32] = core::array::from_fn(|i| {
                let i = i as u16;
                [
                    (i * 37) & ADC_MAX,
                    ADC_MAX - i,
                    (i * 101) & ADC_MAX,
                    (i * 1297) % ENCODER_MODULUS,
                ]
            });
            for (i, s) in samples.iter().enumerate() {
                pack_sample(&mut packed, channels, i, s);
            }
            for (i, s) in samples.iter().enumerate() {
                let got = unpack_sample(&packed, channels, i);
                for c in 0..CHANNEL_COUNT {
                    let want = if channels & (1 << c) != 0 { s[c] } else { 0 };
                    assert_eq!(
                        got[c], want,
                        "channels {channels:04b} sample {i} channel {c}"
                    );
                }
            }
        }
    }
}
