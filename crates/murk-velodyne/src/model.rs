//! The Velodyne sensors whose data packets this crate decodes: their
//! lasers, firing timing and elevations, and how a capture's sensor is
//! told from its packets.
//!
//! These sensors write the same 1206-byte packet: 12 blocks, each an
//! azimuth and 32 channel records. A VLP-16 (or Puck Hi-Res) block holds
//! two firing sequences of its 16 lasers (2.304 µs apart, sequences 55.296
//! µs apart); an HDL-32E block one sequence of its 32 lasers (1.152 µs
//! apart, 46.08 µs a block: 40 slots, 8 of them idle); a VLP-32C block one
//! sequence of its 32 lasers fired in pairs (2.304 µs between pairs, 55.296
//! µs a block), each laser at its own horizontal offset (±1.4°, ±4.2°) and
//! its distances in 4 mm units, not 2. The product byte names the sensor,
//! except that VLP-16 captures tagged 0x21 (the HDL-32E's id) exist: for
//! 0x21 the packet period decides — 1327 µs (VLP-16) or 553 µs (HDL-32E)
//! in single-return mode, half that in dual.
//!
//! ```
//! use murk_velodyne::SensorModel;
//!
//! let hdl = SensorModel::Hdl32e;
//! assert_eq!((hdl.lasers(), hdl.sequences_per_block()), (32, 1));
//! assert_eq!(hdl.elevation_deg()[0], -30.67);
//! assert!((hdl.packet_period_us(false) - 552.96).abs() < 1e-9);
//!
//! // The VLP-32C fires its lasers in pairs: laser 5 with laser 4.
//! let vlp32 = SensorModel::Vlp32c;
//! assert_eq!(vlp32.firing_offset_us(5), vlp32.firing_offset_us(4));
//! assert!((vlp32.firing_offset_us(5) - 2.0 * 2.304).abs() < 1e-12);
//! assert_eq!(vlp32.azimuth_offset_deg()[1], -4.2);
//! assert_eq!(SensorModel::from_product(0x28), Some(vlp32));
//! ```

use murk_types::{
    HDL32E_ELEVATION_DEG, PUCK_HI_RES_ELEVATION_DEG, VLP16_ELEVATION_DEG, VLP32C_ELEVATION_DEG,
};

/// VLP-32C horizontal offset of each laser from the firing azimuth,
/// degrees, by laser id (its default calibration; the VLP-32C manual's
/// "azimuth offset", added to the azimuth).
const VLP32C_AZIMUTH_OFFSET_DEG: [f64; 32] = [
    1.4, -4.2, 1.4, -1.4, 1.4, -1.4, 4.2, -1.4, 1.4, -4.2, 1.4, -1.4, 4.2, -1.4, 4.2, -1.4, 1.4,
    -4.2, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4, 1.4, -1.4, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4,
];

/// No horizontal offsets (lasers in one vertical column).
const NO_OFFSET_DEG: [f64; 32] = [0.0; 32];

/// A Velodyne sensor geometry this crate decodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
#[non_exhaustive]
pub enum SensorModel {
    /// VLP-16 (and the Puck LITE, the same lasers).
    Vlp16,
    /// HDL-32E.
    Hdl32e,
    /// Puck Hi-Res: the VLP-16's packet and timing, lasers over ±10°.
    PuckHiRes,
    /// VLP-32C (Ultra Puck).
    Vlp32c,
}

impl SensorModel {
    /// The sensor a packet's product-id byte names: `None` for products
    /// this crate does not decode. 0x21 is the HDL-32E's id, but VLP-16
    /// captures carry it too (the decoder then tells them by the packet
    /// period).
    pub fn from_product(product: u8) -> Option<Self> {
        match product {
            0x22 | 0x23 => Some(SensorModel::Vlp16),
            0x21 => Some(SensorModel::Hdl32e),
            0x24 => Some(SensorModel::PuckHiRes),
            0x28 => Some(SensorModel::Vlp32c),
            _ => None,
        }
    }

    /// The product-id byte this sensor writes.
    pub fn product(self) -> u8 {
        match self {
            SensorModel::Vlp16 => 0x22,
            SensorModel::Hdl32e => 0x21,
            SensorModel::PuckHiRes => 0x24,
            SensorModel::Vlp32c => 0x28,
        }
    }

    /// Whether packets tagged `product` can come from this sensor: its own
    /// id, and for the VLP-16 also the Puck LITE's and the HDL-32E's (VLP-16
    /// captures tagged 0x21 exist).
    pub fn accepts_product(self, product: u8) -> bool {
        match self {
            SensorModel::Vlp16 => matches!(product, 0x21..=0x23),
            other => product == other.product(),
        }
    }

    /// Lasers (rings; the laser id is the ring).
    pub fn lasers(self) -> usize {
        match self {
            SensorModel::Vlp16 | SensorModel::PuckHiRes => 16,
            SensorModel::Hdl32e | SensorModel::Vlp32c => 32,
        }
    }

    /// Firing sequences of all lasers per block.
    pub fn sequences_per_block(self) -> usize {
        match self {
            SensorModel::Vlp16 | SensorModel::PuckHiRes => 2,
            SensorModel::Hdl32e | SensorModel::Vlp32c => 1,
        }
    }

    /// When `laser` fires after the start of its firing sequence, µs: one
    /// laser every 2.304 µs (VLP-16, Puck Hi-Res) or 1.152 µs (HDL-32E);
    /// the VLP-32C fires its lasers in pairs (0 and 1 together, then 2 and
    /// 3, …), 2.304 µs apart.
    pub fn firing_offset_us(self, laser: usize) -> f64 {
        match self {
            SensorModel::Vlp16 | SensorModel::PuckHiRes => laser as f64 * 2.304,
            SensorModel::Hdl32e => laser as f64 * 1.152,
            SensorModel::Vlp32c => (laser / 2) as f64 * 2.304,
        }
    }

    /// Time between two firing sequences, µs.
    pub fn sequence_period_us(self) -> f64 {
        match self {
            SensorModel::Vlp16 | SensorModel::PuckHiRes | SensorModel::Vlp32c => 55.296,
            SensorModel::Hdl32e => 46.08,
        }
    }

    /// Time one block covers, µs.
    pub fn block_period_us(self) -> f64 {
        self.sequences_per_block() as f64 * self.sequence_period_us()
    }

    /// Time between two data packets, µs (`dual`: dual-return mode, whose
    /// packets hold half as many firing times).
    pub fn packet_period_us(self, dual: bool) -> f64 {
        let single = crate::decode::BLOCKS as f64 * self.block_period_us();
        if dual { single / 2.0 } else { single }
    }

    /// Distance unit of a channel record, metres: 2 mm, the VLP-32C's 4 mm.
    pub fn distance_unit_m(self) -> f64 {
        match self {
            SensorModel::Vlp32c => 0.004,
            _ => 0.002,
        }
    }

    /// Elevation of each laser, degrees, by laser id.
    pub fn elevation_deg(self) -> &'static [f64] {
        match self {
            SensorModel::Vlp16 => &VLP16_ELEVATION_DEG,
            SensorModel::Hdl32e => &HDL32E_ELEVATION_DEG,
            SensorModel::PuckHiRes => &PUCK_HI_RES_ELEVATION_DEG,
            SensorModel::Vlp32c => &VLP32C_ELEVATION_DEG,
        }
    }

    /// Horizontal offset of each laser from the azimuth it fires at,
    /// degrees (clockwise, as the packet's azimuth), by laser id: zero
    /// but for the VLP-32C.
    pub fn azimuth_offset_deg(self) -> &'static [f64] {
        match self {
            SensorModel::Vlp32c => &VLP32C_AZIMUTH_OFFSET_DEG,
            _ => &NO_OFFSET_DEG[..self.lasers()],
        }
    }

    /// The model's name as Velodyne writes it.
    pub fn name(self) -> &'static str {
        match self {
            SensorModel::Vlp16 => "VLP-16",
            SensorModel::Hdl32e => "HDL-32E",
            SensorModel::PuckHiRes => "Puck Hi-Res",
            SensorModel::Vlp32c => "VLP-32C",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_model_has_a_value_for_each_laser() {
        for m in [
            SensorModel::Vlp16,
            SensorModel::Hdl32e,
            SensorModel::PuckHiRes,
            SensorModel::Vlp32c,
        ] {
            assert_eq!(m.elevation_deg().len(), m.lasers(), "{}", m.name());
            assert_eq!(m.azimuth_offset_deg().len(), m.lasers(), "{}", m.name());
            assert_eq!(SensorModel::from_product(m.product()), Some(m));
            assert!(m.accepts_product(m.product()));
            // Every laser fires within its sequence.
            let last = m.firing_offset_us(m.lasers() - 1);
            assert!(last < m.sequence_period_us(), "{}", m.name());
        }
        // The VLP-32C's offsets are ±1.4° and ±4.2°, as many left as right.
        let off = SensorModel::Vlp32c.azimuth_offset_deg();
        assert!(off.iter().all(|o| [1.4, 4.2].contains(&o.abs())));
        assert_eq!(off.iter().filter(|&&o| o > 0.0).count(), 16);
    }
}
