//! The save record: a few bytes the store writes after each blob, under their own map key, so a
//! boot can tell that the newest blob it should find is missing.
//!
//! Why: the map checks every item's CRC and skips a damaged one, returning the item before it
//! (or none). Without a record, a damaged newest blob boots the previous SAVE's values as if
//! they were the newest, and a damaged only blob boots as if nothing had ever been saved. The
//! record names, by tag, the blob its SAVE wrote and the blob a load found before it; it is
//! written after the blob, so a SAVE cut by a power loss before its record leaves the previous
//! record, which matches the previous blob (old settings, nothing to report).
//!
//! At boot ([`SaveRecord::skipped`]): the blob found is the record's `saved` one (all well), or
//! its `replaced` one (the newest blob was skipped: it is damaged), or neither (the record
//! lags: the newest record itself is damaged or was cut, the blob found is the newest).

/// The map key of the save record (the blob's is [`super::store::SETTINGS_KEY`]).
pub const SAVE_RECORD_KEY: u8 = 2;

/// Bytes of a blob's tag.
const TAG_BYTES: usize = 4;

/// Largest encoded record, bytes: two tags.
pub const RECORD_MAX: usize = 2 * TAG_BYTES;

/// A blob's tag: its last four bytes (fewer, zero-padded, for a shorter blob). For an encoded
/// blob that is its CRC-32 ([`super::codec`]), so blobs of different values have different
/// tags; two SAVEs of the same values share a tag, and then which of them loads makes no
/// difference.
pub fn tag(blob: &[u8]) -> u32 {
    let mut t = [0u8; TAG_BYTES];
    let n = blob.len().min(TAG_BYTES);
    t[..n].copy_from_slice(&blob[blob.len() - n..]);
    u32::from_le_bytes(t)
}

/// Which blob a SAVE wrote, and which one a load found just before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SaveRecord {
    /// Tag of the blob this SAVE wrote.
    pub saved: u32,
    /// Tag of the blob a load found before this SAVE (the one the map falls back to if this
    /// SAVE's blob is damaged); `None` if there was none.
    pub replaced: Option<u32>,
}

impl SaveRecord {
    /// The stored form into `out`: `[saved u32][replaced u32]`, little-endian, the second tag
    /// left out when there is none; the bytes used.
    pub fn encode<'a>(&self, out: &'a mut [u8; RECORD_MAX]) -> &'a [u8] {
        out[..TAG_BYTES].copy_from_slice(&self.saved.to_le_bytes());
        match self.replaced {
            Some(r) => {
                out[TAG_BYTES..].copy_from_slice(&r.to_le_bytes());
                &out[..]
            }
            None => &out[..TAG_BYTES],
        }
    }

    /// A stored record, or `None` if `bytes` is not one (the map has checked its CRC already).
    pub fn decode(bytes: &[u8]) -> Option<Self> {
        let word = |i: usize| {
            let w = bytes.get(i * TAG_BYTES..(i + 1) * TAG_BYTES)?;
            Some(u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
        };
        match bytes.len() {
            TAG_BYTES => Some(SaveRecord {
                saved: word(0)?,
                replaced: None,
            }),
            RECORD_MAX => Some(SaveRecord {
                saved: word(0)?,
                replaced: word(1),
            }),
            _ => None,
        }
    }

    /// True if the blob found (tagged `found`) is the one this record's SAVE replaced: the
    /// newer blob the record names was skipped by the map as damaged.
    pub fn skipped(&self, found: u32) -> bool {
        self.saved != found && self.replaced == Some(found)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_round_trips_with_and_without_the_replaced_tag() {
        for r in [
            SaveRecord {
                saved: 0x1234_5678,
                replaced: Some(0x9ABC_DEF0),
            },
            SaveRecord {
                saved: 7,
                replaced: None,
            },
        ] {
            let mut out = [0; RECORD_MAX];
            assert_eq!(SaveRecord::decode(r.encode(&mut out)), Some(r));
        }
        assert_eq!(SaveRecord::decode(&[1, 2, 3]), None);
        assert_eq!(SaveRecord::decode(&[0; 12]), None);
    }

    #[test]
    fn only_the_replaced_blob_counts_as_a_skipped_newest() {
        let r = SaveRecord {
            saved: 2,
            replaced: Some(1),
        };
        assert!(!r.skipped(2), "the newest blob found");
        assert!(
            r.skipped(1),
            "the one before it found: the newest was skipped"
        );
        assert!(
            !r.skipped(3),
            "a newer blob than the record knows: the record lags"
        );
        // The same values saved twice: the older blob is as good as the newest.
        let same = SaveRecord {
            saved: 1,
            replaced: Some(1),
        };
        assert!(!same.skipped(1));
        let first = SaveRecord {
            saved: 1,
            replaced: None,
        };
        assert!(!first.skipped(1) && !first.skipped(0));
    }

    #[test]
    fn the_tag_is_the_last_four_bytes() {
        assert_eq!(tag(&[9, 1, 2, 3, 4]), 0x0403_0201);
        assert_eq!(tag(&[1, 2]), 0x0201);
        assert_eq!(tag(&[]), 0);
    }
}
