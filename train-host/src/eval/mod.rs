//! Evaluation: the baselines the networks are compared with (ICP, PointNetLK).

pub mod icp;
pub mod pointnetlk;
