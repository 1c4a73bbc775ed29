//! The Velodyne sensors whose data packets this crate decodes: their
//! lasers, firing timing and elevations, and how a capture's sensor is
//! told from its packets.
//!
//! Both sensors write the same 1206-byte packet: 12 blocks, each an azimuth
//! and 32 channel records. A VLP-16 block holds two firing sequences of its
//! 16 lasers (2.304 µs apart, sequences 55.296 µs apart); an HDL-32E block
//! one sequence of its 32 lasers (1.152 µs apart, 46.08 µs a block: 40
//! slots, 8 of them idle). The product byte names the sensor, except that
//! VLP-16 captures tagged 0x21 (the HDL-32E's id) exist: for 0x21 the
//! packet period decides — 1327 µs (VLP-16) or 553 µs (HDL-32E) in
//! single-return mode, half that in dual.
//!
//! ```
//! use murk_velodyne::SensorModel;
//!
//! let hdl = SensorModel::Hdl32e;
//! assert_eq!((hdl.lasers(), hdl.sequences_per_block()), (32, 1));
//! assert_eq!(hdl.elevation_deg()[0], -30.67);
//! assert!((hdl.packet_period_us(false) - 552.96).abs() < 1e-9);
//! ```

use murk_types::{HDL32E_ELEVATION_DEG, VLP16_ELEVATION_DEG};

/// A Velodyne sensor geometry this crate decodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
#[non_exhaustive]
pub enum SensorModel {
    /// VLP-16 (and the Puck LITE, the same lasers).
    Vlp16,
    /// HDL-32E.
    Hdl32e,
}

impl SensorModel {
    /// Lasers (rings; the laser id is the ring).
    pub fn lasers(self) -> usize {
        match self {
            SensorModel::Vlp16 => 16,
            SensorModel::Hdl32e => 32,
        }
    }

    /// Firing sequences of all lasers per block.
    pub fn sequences_per_block(self) -> usize {
        match self {
            SensorModel::Vlp16 => 2,
            SensorModel::Hdl32e => 1,
        }
    }

    /// Time between two lasers of a firing sequence, µs.
    pub fn laser_period_us(self) -> f64 {
        match self {
            SensorModel::Vlp16 => 2.304,
            SensorModel::Hdl32e => 1.152,
        }
    }

    /// Time between two firing sequences, µs.
    pub fn sequence_period_us(self) -> f64 {
        match self {
            SensorModel::Vlp16 => 55.296,
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

    /// Elevation of each laser, degrees, by laser id.
    pub fn elevation_deg(self) -> &'static [f64] {
        match self {
            SensorModel::Vlp16 => &VLP16_ELEVATION_DEG,
            SensorModel::Hdl32e => &HDL32E_ELEVATION_DEG,
        }
    }

    /// The model's name as Velodyne writes it.
    pub fn name(self) -> &'static str {
        match self {
            SensorModel::Vlp16 => "VLP-16",
            SensorModel::Hdl32e => "HDL-32E",
        }
    }
}
