//! CRC-32 (IEEE 802.3) of every frame and of a batch's reference samples.

/// CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320, initial value and
/// final XOR 0xFFFFFFFF), table-driven; check value of "123456789" is 0xCBF43926.
#[derive(Clone, Copy, Debug)]
pub struct Crc32 {
    state: u32,
}

const CRC_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut bit = 0;
        while bit < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            bit += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

/// Slicing-by-8 tables (host only, 8 KiB): `CRC_TABLES[j][b]` is the CRC
/// register contribution of byte `b` followed by `j` zero bytes, so eight
/// bytes are folded with eight independent look-ups (Kounavis and Berry,
/// "A systematic approach to building high performance software-based CRC
/// generators", ISCC 2005). The firmware keeps the single 1 KiB table.
#[cfg(feature = "std")]
static CRC_TABLES: [[u32; 256]; 8] = {
    let mut t = [[0u32; 256]; 8];
    t[0] = CRC_TABLE;
    let mut j = 1;
    while j < 8 {
        let mut i = 0;
        while i < 256 {
            let prev = t[j - 1][i];
            t[j][i] = (prev >> 8) ^ CRC_TABLE[(prev & 0xFF) as usize];
            i += 1;
        }
        j += 1;
    }
    t
};

impl Crc32 {
    /// Fresh CRC.
    pub const fn new() -> Self {
        Self { state: 0xFFFF_FFFF }
    }

    /// Feeds bytes.
    pub fn update(&mut self, bytes: &[u8]) {
        let mut c = self.state;
        #[cfg(feature = "std")]
        let bytes = {
            let mut blocks = bytes.chunks_exact(8);
            for b in &mut blocks {
                let lo = c ^ u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                let t = &CRC_TABLES;
                c = t[7][(lo & 0xFF) as usize]
                    ^ t[6][((lo >> 8) & 0xFF) as usize]
                    ^ t[5][((lo >> 16) & 0xFF) as usize]
                    ^ t[4][(lo >> 24) as usize]
                    ^ t[3][b[4] as usize]
                    ^ t[2][b[5] as usize]
                    ^ t[1][b[6] as usize]
                    ^ t[0][b[7] as usize];
            }
            blocks.remainder()
        };
        for &b in bytes {
            c = CRC_TABLE[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8);
        }
        self.state = c;
    }

    /// CRC of everything fed so far.
    pub const fn finish(&self) -> u32 {
        self.state ^ 0xFFFF_FFFF
    }

    /// CRC of `bytes` in one call.
    pub fn checksum(bytes: &[u8]) -> u32 {
        let mut c = Self::new();
        c.update(bytes);
        c.finish()
    }
}

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

/// CRC-32 of the little-endian f32 bits of `references`, as in
/// [`SampleBatch::reference_crc`](super::SampleBatch::reference_crc).
pub fn reference_crc(references: &[f32]) -> u32 {
    let mut c = Crc32::new();
    for r in references {
        c.update(&r.to_le_bytes());
    }
    c.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    #[test]
    fn crc32_matches_check_value() {
        assert_eq!(Crc32::checksum(b"123456789"), 0xCBF4_3926);
        assert_eq!(Crc32::checksum(b""), 0);
    }

    #[test]
    fn crc32_equals_the_bytewise_table_at_every_length_and_alignment() {
        let mut rng = SplitMix64::new(11);
        let data: Vec<u8> = (0..200).map(|_| rng.next_u64() as u8).collect();
        for start in 0..9 {
            for end in start..data.len() {
                let mut c = 0xFFFF_FFFFu32;
                for &b in &data[start..end] {
                    c = CRC_TABLE[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8);
                }
                // also fed in two uneven parts
                let mid = start + (end - start) / 3;
                let mut two = Crc32::new();
                two.update(&data[start..mid]);
                two.update(&data[mid..end]);
                assert_eq!(Crc32::checksum(&data[start..end]), !c, "{start}..{end}");
                assert_eq!(two.finish(), !c, "{start}..{end} in two parts");
            }
        }
    }
}
