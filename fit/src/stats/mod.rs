//! Generic statistics on in-memory values: distributions, a minimiser,
//! quantiles, regressions, truncated-normal and Poisson likelihood fits, and
//! the bootstrap. Nothing here knows about LiDAR, campaigns or files.

pub mod bootstrap;
pub mod counts;
pub mod dist;
pub mod optim;
pub mod quantile;
pub mod regress;
pub mod truncnorm;
