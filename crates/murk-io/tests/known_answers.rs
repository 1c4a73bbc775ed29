//! Hand-written files with known contents: the readers must return exactly
//! these points.

mod common;

use std::path::Path;

use common::{f32s, file};
use murk_io::{
    PcdData, ReadOptions, parse_csv, parse_kitti, parse_nuscenes, parse_pcd, read_cloud,
    read_frames,
};
use murk_types::{IntensityScale, LidarSpec, PointCloud, PointFormat};

fn opts() -> ReadOptions {
    ReadOptions::default()
}

/// The header the Velodyne ROS driver writes (fields x y z intensity ring
/// time; intensity F4, ring U2, time F4).
const ROS_HEADER: &str = "# .PCD v0.7 - Point Cloud Data file format
VERSION 0.7
FIELDS x y z intensity ring time
SIZE 4 4 4 4 2 4
TYPE F F F F U F
COUNT 1 1 1 1 1 1
WIDTH 3
HEIGHT 1
VIEWPOINT 0 0 0 1 0 0 0
POINTS 3
DATA ascii
";

#[test]
fn velodyne_ros_ascii_pcd_reads_exactly() {
    let text = format!(
        "{ROS_HEADER}1.5 -2.25 0.125 17 3 0.0001\n\
         10 0 -1.75 104 0 0.05\n\
         -0.5 7.25 2 0 15 0.099\n"
    );
    let c = parse_pcd(text.as_bytes(), Path::new("ros.pcd"), &opts()).unwrap();
    assert_eq!(c.x, vec![1.5, 10.0, -0.5]);
    assert_eq!(c.y, vec![-2.25, 0.0, 7.25]);
    assert_eq!(c.z, vec![0.125, -1.75, 2.0]);
    assert_eq!(c.intensity, vec![17.0, 104.0, 0.0]);
    assert_eq!(c.ring, vec![3, 0, 15]);
    assert_eq!(c.time, Some(vec![0.0001, 0.05, 0.099]));
    assert_eq!(c.intensity_scale, IntensityScale::Calibrated);
}

#[test]
fn ascii_pcd_with_crlf_comments_and_blank_lines_reads() {
    let text = "# comment\r\nVERSION .7\r\nFIELDS x y z intensity\r\nSIZE 4 4 4 4\r\nTYPE F F F F\r\n\
                WIDTH 2\r\nHEIGHT 1\r\nPOINTS 2\r\nDATA ascii\r\n1 2 3 4\r\n\r\n5 6 7 8\r\n\r\n";
    let c = parse_pcd(text.as_bytes(), Path::new("crlf.pcd"), &opts()).unwrap();
    assert_eq!(c.x, vec![1.0, 5.0]);
    assert_eq!(c.intensity, vec![4.0, 8.0]);
}

#[test]
fn binary_pcd_in_any_field_order_and_type_reads_exactly() {
    // intensity U1, ring U2, x F8, an unknown `return_type` U1, y I2, z F4,
    // `_` padding of 3 bytes, time F8 holding absolute epoch seconds.
    let header = "VERSION 0.7\nFIELDS intensity ring x return_type y z _ time\n\
                  SIZE 1 2 8 1 2 4 1 8\nTYPE U U F U I F U F\nCOUNT 1 1 1 1 1 1 3 1\n\
                  WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n";
    let mut b = header.as_bytes().to_vec();
    let rows: [(u8, u16, f64, u8, i16, f32, f64); 2] = [
        (200, 7, 1.25, 9, -3, 0.5, 1_700_000_000.0),
        (4, 12, -8.5, 9, 40, -1.0, 1_700_000_000.062_5),
    ];
    for (i, r, x, rt, y, z, t) in rows {
        b.push(i);
        b.extend(r.to_le_bytes());
        b.extend(x.to_le_bytes());
        b.push(rt);
        b.extend(y.to_le_bytes());
        b.extend(z.to_le_bytes());
        b.extend([0xAB; 3]);
        b.extend(t.to_le_bytes());
    }
    let c = parse_pcd(&b, Path::new("mixed.pcd"), &opts()).unwrap();
    assert_eq!(c.x, vec![1.25, -8.5]);
    assert_eq!(c.y, vec![-3.0, 40.0]);
    assert_eq!(c.z, vec![0.5, -1.0]);
    assert_eq!(c.intensity, vec![200.0, 4.0]);
    assert_eq!(c.ring, vec![7, 12]);
    // Absolute F8 times are made relative to the first point.
    assert_eq!(c.time, Some(vec![0.0, 0.0625]));
}

#[test]
fn pcl_binary_compressed_skips_padding_fields() {
    // PCL's layout: `_` fields take no room in the compressed block; each
    // field's values are contiguous. Literal-only LZF (control byte len-1).
    let header = "VERSION 0.7\nFIELDS x y z _ intensity\nSIZE 4 4 4 1 4\nTYPE F F F U F\n\
                  COUNT 1 1 1 4 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary_compressed\n";
    let soa = f32s(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 70.0, 80.0]);
    let mut lzf = vec![31u8];
    lzf.extend(&soa);
    let mut b = header.as_bytes().to_vec();
    b.extend((lzf.len() as u32).to_le_bytes());
    b.extend((soa.len() as u32).to_le_bytes());
    b.extend(&lzf);
    let c = parse_pcd(&b, Path::new("pcl.pcd"), &opts()).unwrap();
    assert_eq!(c.x, vec![1.0, 2.0]);
    assert_eq!(c.y, vec![3.0, 4.0]);
    assert_eq!(c.z, vec![5.0, 6.0]);
    assert_eq!(c.intensity, vec![70.0, 80.0]);
}

#[test]
fn pcd_without_ring_derives_it_from_elevation() {
    // Points at 15°, -15°, 1° and -1° elevation: VLP-16 ids 15, 0, 1, 14.
    let mut text = String::from(
        "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH 4\nHEIGHT 1\nDATA ascii\n",
    );
    for el in [15.0f64, -15.0, 1.0, -1.0] {
        let r = 20.0;
        let (x, z) = (r * el.to_radians().cos(), r * el.to_radians().sin());
        text.push_str(&format!("{x} 0 {z} 5\n"));
    }
    let c = parse_pcd(text.as_bytes(), Path::new("noring.pcd"), &opts()).unwrap();
    assert_eq!(c.ring, vec![15, 0, 1, 14]);
    // A different sensor gives different rings.
    let spec = LidarSpec {
        elevation_deg: vec![-10.0, 10.0],
        ..LidarSpec::vlp16()
    };
    let o = ReadOptions {
        lidar: Some(spec),
        ..ReadOptions::default()
    };
    let c = parse_pcd(text.as_bytes(), Path::new("noring.pcd"), &o).unwrap();
    assert_eq!(c.ring, vec![1, 0, 1, 0]);
}

#[test]
fn veloview_csv_export_reads_with_quoted_headers_and_extra_columns() {
    // The column set VeloView 5 writes for a VLP-16 frame.
    let text = "\"Points_m_XYZ:0\",\"Points_m_XYZ:1\",\"Points_m_XYZ:2\",\"X\",\"Y\",\"Z\",\
                \"intensity\",\"laser_id\",\"azimuth\",\"distance_m\",\"adjustedtime\",\"timestamp\",\
                \"vertical_angle\",\"dual_distance\",\"dual_intensity\",\"dual_return_matching\"\n\
                3.5243,-0.0123,-0.9444,3.5243,-0.0123,-0.9444,5,0,35978,3.6486,2816493107,2816493107,-15,0,0,-1\n\
                3.9001,-0.0138,0.0681,3.9001,-0.0138,0.0681,12,1,35978,3.9007,2816493109,2816493109,1,0,0,-1\n";
    let c = parse_csv(text.as_bytes(), Path::new("frame.csv"), &opts()).unwrap();
    assert_eq!(c.x, vec![3.5243, 3.9001]);
    assert_eq!(c.y, vec![-0.0123, -0.0138]);
    assert_eq!(c.z, vec![-0.9444, 0.0681]);
    assert_eq!(c.intensity, vec![5.0, 12.0]);
    assert_eq!(c.ring, vec![0, 1]);
    assert_eq!(c.time, None);
}

#[test]
fn plain_csv_without_ring_derives_it_and_reads_time() {
    let text = "time, z ,y,x,intensity\n0.25,0,0,10,3\n0.5,-10,0,0.0001,4\n";
    let c = parse_csv(text.as_bytes(), Path::new("plain.csv"), &opts()).unwrap();
    assert_eq!(c.x, vec![10.0, 0.0001]);
    assert_eq!(c.z, vec![0.0, -10.0]);
    // 0° elevation → id 1 (+1°, tie with -1° goes to the lower id); straight down → id 0.
    assert_eq!(c.ring, vec![1, 0]);
    assert_eq!(c.time, Some(vec![0.25, 0.5]));
}

#[test]
fn kitti_bin_reads_exactly_with_kitti_scale_unless_overridden() {
    let b = f32s(&[10.0, 0.0, 0.0, 0.25, 0.0, 5.0, -5.0, 1.0]);
    let c = parse_kitti(&b, Path::new("000000.bin"), &opts()).unwrap();
    assert_eq!(c.x, vec![10.0, 0.0]);
    assert_eq!(c.y, vec![0.0, 5.0]);
    assert_eq!(c.z, vec![0.0, -5.0]);
    // 0° → id 1; -45° → the lowest ring, id 0 (-15°).
    assert_eq!(c.ring, vec![1, 0]);
    assert_eq!(c.intensity, vec![0.25, 1.0]);
    assert_eq!(c.intensity_scale, IntensityScale::KITTI);
    let o = ReadOptions {
        intensity_scale: Some(IntensityScale::Calibrated),
        ..ReadOptions::default()
    };
    let c = parse_kitti(&b, Path::new("000000.bin"), &o).unwrap();
    assert_eq!(c.intensity_scale, IntensityScale::Calibrated);
    assert_eq!(c.intensity, vec![0.25, 1.0], "readers never convert");
}

#[test]
fn the_campaign_lidar_scale_applies_when_no_explicit_scale_is_given() {
    let b = f32s(&[10.0, 0.0, 0.0, 0.25]);
    let spec = LidarSpec {
        intensity_scale: Some(IntensityScale::SIX_BIT),
        ..LidarSpec::vlp16()
    };
    let o = ReadOptions {
        lidar: Some(spec),
        ..ReadOptions::default()
    };
    let c = parse_kitti(&b, Path::new("000000.bin"), &o).unwrap();
    assert_eq!(c.intensity_scale, IntensityScale::SIX_BIT);
}

#[test]
fn nuscenes_bin_reads_exactly() {
    let b = f32s(&[1.0, 2.0, 3.0, 40.0, 31.0, -1.0, -2.0, -3.0, 0.0, 0.0]);
    let c = parse_nuscenes(&b, Path::new("x.pcd.bin"), &opts()).unwrap();
    assert_eq!(c.x, vec![1.0, -1.0]);
    assert_eq!(c.intensity, vec![40.0, 0.0]);
    assert_eq!(c.ring, vec![31, 0]);
    assert_eq!(c.intensity_scale, IntensityScale::Calibrated);
}

#[test]
fn forced_format_overrides_the_extension() {
    let dir = tempfile::tempdir().unwrap();
    let p = file(dir.path(), "points.dat", &f32s(&[1.0, 2.0, 3.0, 0.5]));
    let o = ReadOptions {
        format: Some(PointFormat::KittiBin),
        ..ReadOptions::default()
    };
    let c = read_cloud(&p, &o).unwrap();
    assert_eq!(c.len(), 1);
}

#[test]
fn read_frames_of_a_single_scan_file_is_that_scan() {
    let dir = tempfile::tempdir().unwrap();
    let p = file(dir.path(), "a.csv", b"x,y,z,intensity,ring\n1,2,3,4,5\n");
    let frames = read_frames(&p, &opts()).unwrap();
    let mut want = PointCloud::with_capacity(1);
    want.push(1.0, 2.0, 3.0, 4.0, 5);
    assert_eq!(frames, vec![want]);
}

#[test]
fn pcd_data_names_parse_and_print() {
    for d in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
        assert_eq!(d.name().parse::<PcdData>().unwrap(), d);
    }
    assert!("zip".parse::<PcdData>().is_err());
}
