//! factory-engine: the contact pipeline of Factory (Narang et al., RSS 2022, section III) on wgpu.
//!
//! Data flows one way: triangle meshes ([`mesh`]) and URDFs ([`urdf`]) are loaded on the host, signed
//! distance fields are baked on the CPU and cached on disk ([`sdf`]), and the GPU ([`gpu`]) generates one
//! contact candidate per query triangle against the opposing SDF and reduces the candidates into patches in
//! workgroup memory ([`contact`]). A Gauss-Seidel solver steps the bodies ([`solver`]: one invocation per
//! world for many small worlds; [`many_body`]: near pairs found per frame and graph-coloured for worlds of many
//! bodies). [`sim`] steps worlds where an articulation ([`articulation`]: the Franka in joint coordinates)
//! and free bodies touch, on top of the builder, the contact pipeline and the solver. Every kernel has a
//! plain-Rust twin used by parity tests.

pub mod error;
pub mod mesh;

pub use error::{EngineError, Result};
/// The wgpu the engine is built on (callers that record their own command encoders use this one).
pub use wgpu;
pub mod articulation;
pub mod builder;
pub mod contact;
pub mod fsutil;
pub mod gpu;
pub mod many_body;
pub mod rng;
pub mod sdf;
pub mod sim;
pub mod solver;
pub mod urdf;
