//! factory-bench: the scenes and measurements behind `factory-bench` (paper Tables I and II) and the
//! accuracy tests that share them.

pub mod cli;
pub mod contact_scene;
pub mod franka;
pub mod pareto;
pub mod pile;
pub mod scene;
