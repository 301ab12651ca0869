//! The stored form of [`Settings`]: a versioned, CRC-checked blob.
//!
//! Layout (little-endian): `[FORMAT_VERSION: u8][count: u8][value: f32; count][crc32: u32]`,
//! the CRC-32 (ISO-HDLC, as zlib's) over everything before it. Values are in registry order.
//! Decoding checks, in order: length, CRC, version, count, then every value against its
//! setting's current range; the first failure is the reason the defaults are used.

use super::Settings;

/// The stored layout's version. Raise it whenever the registry's groups, order or meaning of a
/// value change: an older blob then loads as the defaults (`reason=old-format`), never as
/// values shifted into the wrong settings. Settings appended at the registry's end need no new
/// version: a blob from before them holds every value before them, in place, and loads with
/// the appended ones at their defaults (down to [`FORMAT_BASE_COUNT`] values).
pub const FORMAT_VERSION: u8 = 5;

/// How many values the registry held when [`FORMAT_VERSION`] was last raised: a blob of this
/// version holds at least these (`calibration::Calibration::tca_strain_sd_share` was appended
/// after them).
pub const FORMAT_BASE_COUNT: usize = 24;

/// Largest blob, bytes: room for 32 settings (the morph group has 7, the calibration 17).
pub const BLOB_MAX: usize = 2 + 4 * 32 + 4;

/// CRC-32/ISO-HDLC without a lookup table (the blob is a few dozen bytes; a table would cost
/// 1 KiB of flash for nothing).
const CRC: crc::Crc<u32, crc::NoTable> = crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISO_HDLC);

/// An encoded settings blob.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Blob {
    bytes: [u8; BLOB_MAX],
    len: usize,
}

impl Blob {
    /// The encoded bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

/// Why stored settings were not used (the defaults were, and `event: config defaults
/// reason=<word>` says why).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LoadError {
    /// Nothing stored (a new board, or never saved).
    Absent,
    /// Shorter than its header and CRC, or than its count says.
    Truncated,
    /// The CRC does not match: the blob is damaged.
    Corrupt,
    /// Written by another layout version.
    OldFormat(u8),
    /// The count of values does not match this firmware's registry.
    WrongCount(u8),
    /// A stored value lies outside its setting's current range (the setting's name).
    OutOfRange(&'static str),
    /// The flash could not be read (or its storage is damaged beyond the blob).
    Flash,
}

impl LoadError {
    /// The `reason=` word.
    pub fn as_str(&self) -> &'static str {
        match self {
            LoadError::Absent => "absent",
            LoadError::Truncated => "truncated",
            LoadError::Corrupt => "crc-mismatch",
            LoadError::OldFormat(_) => "old-format",
            LoadError::WrongCount(_) => "wrong-count",
            LoadError::OutOfRange(_) => "out-of-range",
            LoadError::Flash => "flash-error",
        }
    }
}

/// Encodes `s` (every current value, in registry order).
pub fn encode(s: &Settings) -> Blob {
    let mut bytes = [0u8; BLOB_MAX];
    let mut len = 2;
    let mut count = 0u8;
    s.for_each(|_, v| {
        if len + 4 + 4 <= BLOB_MAX {
            bytes[len..len + 4].copy_from_slice(&v.to_le_bytes());
            len += 4;
            count += 1;
        }
    });
    bytes[0] = FORMAT_VERSION;
    bytes[1] = count;
    let crc = CRC.checksum(&bytes[..len]);
    bytes[len..len + 4].copy_from_slice(&crc.to_le_bytes());
    len += 4;
    Blob { bytes, len }
}

/// Decodes a stored blob into settings, or says why it cannot be used.
pub fn decode(bytes: &[u8]) -> Result<Settings, LoadError> {
    if bytes.len() < 2 + 4 {
        return Err(LoadError::Truncated);
    }
    let (body, crc) = bytes.split_at(bytes.len() - 4);
    let stored = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if CRC.checksum(body) != stored {
        // A blob cut short also fails here unless its count says otherwise; tell them apart.
        let expected_len = 2 + 4 * body[1] as usize + 4;
        return Err(if bytes.len() < expected_len {
            LoadError::Truncated
        } else {
            LoadError::Corrupt
        });
    }
    if body[0] != FORMAT_VERSION {
        return Err(LoadError::OldFormat(body[0]));
    }
    let mut s = Settings::DEFAULT;
    let count = body[1] as usize;
    if !(FORMAT_BASE_COUNT..=s.count()).contains(&count) {
        return Err(LoadError::WrongCount(body[1]));
    }
    if body.len() != 2 + 4 * count {
        return Err(LoadError::Truncated);
    }
    // Values past the blob's end were appended after it was written: their defaults stay.
    let mut values = body[2..].chunks_exact(4);
    for g in s.groups_mut() {
        for (i, spec) in g.specs().iter().enumerate() {
            let Some(w) = values.next() else {
                break;
            };
            let v = f32::from_le_bytes([w[0], w[1], w[2], w[3]]);
            if !spec.allows(v) {
                return Err(LoadError::OutOfRange(spec.name));
            }
            g.set(i, v);
        }
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    extern crate std;
    use std::vec::Vec;

    fn changed() -> Settings {
        let mut s = Settings::DEFAULT;
        s.set_text("soften_timeout_s", "42").unwrap();
        s.set_text("auto_mode", "boost").unwrap();
        s.set_text("pla_soft_target_c", "80.5").unwrap();
        s
    }

    /// Re-seals a hand-edited body with a good CRC.
    fn sealed(body: &[u8]) -> Vec<u8> {
        let mut v = body.to_vec();
        v.extend_from_slice(&CRC.checksum(body).to_le_bytes());
        v
    }

    #[test]
    fn a_blob_round_trips_and_has_the_documented_size() {
        let s = changed();
        let b = encode(&s);
        assert_eq!(b.as_bytes().len(), 2 + 4 * s.count() + 4);
        assert_eq!(b.as_bytes().len(), 106, "docs/settings.md gives 106 bytes");
        assert_eq!(decode(b.as_bytes()), Ok(s));
        assert_eq!(
            decode(encode(&Settings::DEFAULT).as_bytes()),
            Ok(Settings::DEFAULT)
        );
    }

    #[test]
    fn any_flipped_bit_is_caught() {
        let b = encode(&changed());
        let bytes = b.as_bytes();
        for i in 0..bytes.len() * 8 {
            let mut v = bytes.to_vec();
            v[i / 8] ^= 1 << (i % 8);
            assert!(decode(&v).is_err(), "bit {i} flipped went unnoticed");
        }
    }

    #[test]
    fn a_cut_blob_is_truncated() {
        let b = encode(&changed());
        let bytes = b.as_bytes();
        for n in 0..bytes.len() {
            let e = decode(&bytes[..n]).unwrap_err();
            assert!(
                matches!(e, LoadError::Truncated | LoadError::Corrupt),
                "{n}: {e:?}"
            );
        }
        assert_eq!(decode(&bytes[..3]), Err(LoadError::Truncated));
        assert_eq!(decode(&bytes[..bytes.len() - 1]), Err(LoadError::Truncated));
    }

    #[test]
    fn another_version_or_count_is_refused() {
        let b = encode(&changed());
        let body = &b.as_bytes()[..b.as_bytes().len() - 4];
        let mut old = body.to_vec();
        old[0] = 0;
        assert_eq!(decode(&sealed(&old)), Err(LoadError::OldFormat(0)));
        let base = 2 + 4 * FORMAT_BASE_COUNT;
        let mut short = body[..base - 4].to_vec();
        short[1] = FORMAT_BASE_COUNT as u8 - 1;
        assert_eq!(
            decode(&sealed(&short)),
            Err(LoadError::WrongCount(FORMAT_BASE_COUNT as u8 - 1))
        );
        let mut long = body.to_vec();
        long.extend_from_slice(&0f32.to_le_bytes());
        long[1] += 1;
        assert_eq!(decode(&sealed(&long)), Err(LoadError::WrongCount(long[1])));
    }

    #[test]
    fn a_blob_from_before_settings_were_appended_loads_them_at_their_defaults() {
        let mut c = changed();
        c.cal.tca_strain_sd_share = 0.5;
        let b = encode(&c);
        let body = &b.as_bytes()[..b.as_bytes().len() - 4];
        let mut before = body[..2 + 4 * FORMAT_BASE_COUNT].to_vec();
        before[1] = FORMAT_BASE_COUNT as u8;
        let s = decode(&sealed(&before)).unwrap();
        assert_eq!(s.morph, c.morph);
        assert_eq!(s.cal.tca_strain_sd_share, 0.0);
        assert_eq!(s.cal.version, c.cal.version);
    }

    #[test]
    fn a_stored_value_outside_its_range_is_refused() {
        let b = encode(&Settings::DEFAULT);
        let body = &b.as_bytes()[..b.as_bytes().len() - 4];
        // soften_timeout_s is the fifth value: 2 header bytes + 4 values.
        for bad in [1000.0f32, -1.0, f32::NAN, f32::INFINITY] {
            let mut v = body.to_vec();
            v[2 + 16..2 + 20].copy_from_slice(&bad.to_le_bytes());
            assert_eq!(
                decode(&sealed(&v)),
                Err(LoadError::OutOfRange("soften_timeout_s"))
            );
        }
        // A choice index that is not whole, or past its words.
        for bad in [1.5f32, 4.0] {
            let mut v = body.to_vec();
            v[2..6].copy_from_slice(&bad.to_le_bytes());
            assert_eq!(decode(&sealed(&v)), Err(LoadError::OutOfRange("auto_mode")));
        }
    }
}
