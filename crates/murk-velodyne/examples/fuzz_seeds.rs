//! Writes the seed corpus of the `pcap` fuzz target (see `fuzz/README.md`).
//!
//! `cargo run -p murk-velodyne --example fuzz_seeds -- crates/murk-velodyne/fuzz/seeds/pcap`
//!
//! Each seed is one options byte (read by the fuzz target) followed by a
//! small synthetic capture.

use std::path::PathBuf;

use murk_velodyne::ReturnMode;
use murk_velodyne::synth::{PcapWriter, Sweep, ethernet_arp, ethernet_udp};

fn main() -> std::io::Result<()> {
    let dir = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| ".".into()));
    std::fs::create_dir_all(&dir)?;
    let single = Sweep {
        packets: 3,
        position_every: 2,
        start_azimuth_deg: 359.0,
        ..Sweep::default()
    };
    let dual = Sweep {
        packets: 2,
        mode: ReturnMode::Dual,
        ..Sweep::default()
    };
    // Big-endian, nanosecond, with a foreign ARP frame between data packets.
    let mut mixed = PcapWriter::new(1, true, true);
    for (i, p) in single.data_packets().iter().enumerate() {
        mixed.push(
            1,
            0,
            &ethernet_udp(&p.to_payload(), murk_velodyne::DATA_PORT),
        );
        if i == 0 {
            mixed.push(1, 0, &ethernet_arp());
        }
    }
    let seeds = [
        ("seed-single", 0u8, single.to_pcap()),
        ("seed-dual", 0u8, dual.to_pcap()),
        ("seed-mixed-be-ns", 1u8, mixed.into_bytes()),
    ];
    for (name, knob, bytes) in seeds {
        let mut data = vec![knob];
        data.extend(bytes);
        std::fs::write(dir.join(name), &data)?;
        println!("{name}: {} bytes", data.len());
    }
    Ok(())
}
