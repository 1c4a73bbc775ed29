//! The in-memory LiDAR scan.

use crate::IntensityScale;
use crate::TypesError;

/// A LiDAR scan as columns (structure of arrays).
///
/// Coordinates are metres in the sensor frame (x forward, y left, z up).
/// `intensity` is in the scale named by [`PointCloud::intensity_scale`]; call
/// [`PointCloud::to_calibrated`] before comparing it with reflectivity bands.
/// `ring` is the laser id (derived from elevation for formats that lack it).
/// `time` is seconds relative to the first packet of the scan when the source
/// has it.
///
/// Columns are public so that hot loops can run over slices; every column has
/// the same length, which [`PointCloud::check`] verifies.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    /// x coordinates, metres.
    pub x: Vec<f32>,
    /// y coordinates, metres.
    pub y: Vec<f32>,
    /// z coordinates, metres.
    pub z: Vec<f32>,
    /// Intensity in [`PointCloud::intensity_scale`].
    pub intensity: Vec<f32>,
    /// Ring (laser) id.
    pub ring: Vec<u16>,
    /// Optional per-point time in seconds.
    pub time: Option<Vec<f32>>,
    /// Scale of `intensity`.
    pub intensity_scale: IntensityScale,
}

impl PointCloud {
    /// An empty cloud with room for `n` points, calibrated intensity scale.
    pub fn with_capacity(n: usize) -> Self {
        PointCloud {
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            z: Vec::with_capacity(n),
            intensity: Vec::with_capacity(n),
            ring: Vec::with_capacity(n),
            time: None,
            intensity_scale: IntensityScale::Calibrated,
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True when the cloud has no point.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Appends one point (no time).
    ///
    /// # Panics
    /// When the cloud carries a time column: use [`PointCloud::push_timed`].
    pub fn push(&mut self, x: f32, y: f32, z: f32, intensity: f32, ring: u16) {
        assert!(
            self.time.is_none(),
            "cloud has a time column: use push_timed"
        );
        self.x.push(x);
        self.y.push(y);
        self.z.push(z);
        self.intensity.push(intensity);
        self.ring.push(ring);
    }

    /// Appends one point with its time, creating the time column when the
    /// cloud is empty.
    ///
    /// # Panics
    /// When the cloud already holds points without time.
    pub fn push_timed(&mut self, x: f32, y: f32, z: f32, intensity: f32, ring: u16, time: f32) {
        if self.time.is_none() {
            assert!(self.is_empty(), "cloud has points without time");
            self.time = Some(Vec::with_capacity(self.x.capacity()));
        }
        self.x.push(x);
        self.y.push(y);
        self.z.push(z);
        self.intensity.push(intensity);
        self.ring.push(ring);
        if let Some(t) = self.time.as_mut() {
            t.push(time);
        }
    }

    /// Range (Euclidean distance from the sensor) of point `i`, metres.
    #[inline]
    pub fn range(&self, i: usize) -> f32 {
        (self.x[i] * self.x[i] + self.y[i] * self.y[i] + self.z[i] * self.z[i]).sqrt()
    }

    /// Azimuth of point `i` in degrees, in [0, 360), counter-clockwise from x.
    #[inline]
    pub fn azimuth_deg(&self, i: usize) -> f32 {
        let a = self.y[i].atan2(self.x[i]).to_degrees();
        if a < 0.0 { a + 360.0 } else { a }
    }

    /// Elevation of point `i` in degrees above the x–y plane.
    #[inline]
    pub fn elevation_deg(&self, i: usize) -> f32 {
        let h = (self.x[i] * self.x[i] + self.y[i] * self.y[i]).sqrt();
        self.z[i].atan2(h).to_degrees()
    }

    /// Converts `intensity` to calibrated VLP-16 reflectivity in place.
    pub fn to_calibrated(&mut self) {
        let scale = self.intensity_scale;
        if scale != IntensityScale::Calibrated {
            for v in &mut self.intensity {
                *v = scale.to_calibrated(*v);
            }
            self.intensity_scale = IntensityScale::Calibrated;
        }
    }

    /// Converts calibrated `intensity` back to `scale` in place (the inverse of
    /// [`PointCloud::to_calibrated`]), e.g. to write a degraded KITTI scan in
    /// KITTI's own 0–1 convention.
    pub fn to_scale(&mut self, scale: IntensityScale) {
        self.to_calibrated();
        if scale != IntensityScale::Calibrated {
            for v in &mut self.intensity {
                *v = scale.from_calibrated(*v);
            }
        }
        self.intensity_scale = scale;
    }

    /// Keeps the points whose `keep` flag is true, in order.
    ///
    /// # Panics
    /// When `keep.len() != self.len()`.
    pub fn retain_mask(&mut self, keep: &[bool]) {
        assert_eq!(keep.len(), self.len(), "mask length");
        fn filt<T: Copy>(v: &mut Vec<T>, keep: &[bool]) {
            let mut w = 0;
            for r in 0..v.len() {
                if keep[r] {
                    v[w] = v[r];
                    w += 1;
                }
            }
            v.truncate(w);
        }
        filt(&mut self.x, keep);
        filt(&mut self.y, keep);
        filt(&mut self.z, keep);
        filt(&mut self.intensity, keep);
        filt(&mut self.ring, keep);
        if let Some(t) = self.time.as_mut() {
            filt(t, keep);
        }
    }

    /// Appends all points of `other` (which must agree on scale and on the
    /// presence of time; `other`'s intensities are converted when the scales
    /// differ).
    pub fn extend_from(&mut self, other: &PointCloud) -> Result<(), TypesError> {
        if self.time.is_some() != other.time.is_some() && !(self.is_empty() && self.time.is_none())
        {
            return Err(TypesError::RaggedCloud(
                "one cloud has a time column and the other does not".into(),
            ));
        }
        let was_empty = self.is_empty();
        self.x.extend_from_slice(&other.x);
        self.y.extend_from_slice(&other.y);
        self.z.extend_from_slice(&other.z);
        if other.intensity_scale == self.intensity_scale {
            self.intensity.extend_from_slice(&other.intensity);
        } else {
            let (from, to) = (other.intensity_scale, self.intensity_scale);
            self.intensity.extend(
                other
                    .intensity
                    .iter()
                    .map(|&v| to.from_calibrated(from.to_calibrated(v))),
            );
        }
        self.ring.extend_from_slice(&other.ring);
        match (&mut self.time, &other.time) {
            (Some(a), Some(b)) => a.extend_from_slice(b),
            (None, Some(b)) if was_empty => self.time = Some(b.clone()),
            _ => {}
        }
        Ok(())
    }

    /// Verifies that every column has the same length.
    pub fn check(&self) -> Result<(), TypesError> {
        let n = self.x.len();
        let lens = [
            ("y", self.y.len()),
            ("z", self.z.len()),
            ("intensity", self.intensity.len()),
            ("ring", self.ring.len()),
            ("time", self.time.as_ref().map_or(n, Vec::len)),
        ];
        for (name, len) in lens {
            if len != n {
                return Err(TypesError::RaggedCloud(format!(
                    "column {name} has {len} values, x has {n}"
                )));
            }
        }
        Ok(())
    }

    /// Index of the first point with a non-finite coordinate or intensity.
    pub fn first_non_finite(&self) -> Option<usize> {
        (0..self.len()).find(|&i| {
            !(self.x[i].is_finite()
                && self.y[i].is_finite()
                && self.z[i].is_finite()
                && self.intensity[i].is_finite())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud() -> PointCloud {
        let mut c = PointCloud::with_capacity(3);
        c.push(3.0, 4.0, 0.0, 10.0, 1);
        c.push(0.0, -2.0, 0.0, 20.0, 2);
        c.push(1.0, 0.0, 1.0, 30.0, 3);
        c
    }

    #[test]
    fn geometry_of_a_point() {
        let c = cloud();
        assert_eq!(c.range(0), 5.0);
        assert!((c.azimuth_deg(1) - 270.0).abs() < 1e-4);
        assert!((c.elevation_deg(2) - 45.0).abs() < 1e-4);
    }

    #[test]
    fn retain_mask_keeps_order_and_columns() {
        let mut c = cloud();
        c.retain_mask(&[true, false, true]);
        assert_eq!(c.x, vec![3.0, 1.0]);
        assert_eq!(c.intensity, vec![10.0, 30.0]);
        assert_eq!(c.ring, vec![1, 3]);
        c.check().unwrap();
    }

    #[test]
    fn scale_round_trip() {
        let mut c = cloud();
        c.intensity = vec![0.0, 0.5, 1.0];
        c.intensity_scale = IntensityScale::KITTI;
        c.to_calibrated();
        assert_eq!(c.intensity, vec![0.0, 127.5, 255.0]);
        c.to_scale(IntensityScale::KITTI);
        assert_eq!(c.intensity, vec![0.0, 0.5, 1.0]);
    }

    #[test]
    fn ragged_columns_are_reported() {
        let mut c = cloud();
        c.ring.pop();
        let e = c.check().unwrap_err().to_string();
        assert!(e.contains("ring has 2 values, x has 3"), "{e}");
    }

    #[test]
    fn non_finite_is_found() {
        let mut c = cloud();
        c.z[1] = f32::NAN;
        assert_eq!(c.first_non_finite(), Some(1));
    }
}
