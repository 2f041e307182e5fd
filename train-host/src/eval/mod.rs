//! Evaluation: the classical baseline (ICP) the networks are compared with.

pub mod icp;
