//! Point-cloud readers and writers (skeleton: being filled in).
#![allow(missing_docs, unused_variables)]
use murk_types::{IntensityScale, LidarSpec, PointCloud, PointFormat};
use std::path::Path;

#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    pub format: Option<PointFormat>,
    pub lidar: Option<LidarSpec>,
    pub intensity_scale: Option<IntensityScale>,
}

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IoError {
    #[error("{0}")]
    Other(String),
}

pub fn read_cloud(path: &Path, opts: &ReadOptions) -> Result<PointCloud, IoError> {
    todo!()
}

pub fn write_cloud(path: &Path, cloud: &PointCloud, format: PointFormat) -> Result<(), IoError> {
    todo!()
}
