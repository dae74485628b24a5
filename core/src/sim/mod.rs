// SPDX-License-Identifier: MIT
//! Simulation: scenes whose geometry is known exactly, rendered by CPU ray casting, for tests
//! and benchmarks with exact answers, and seed 000's virtual depth sensor ([`sensor`]), which
//! renders a fused map at any pose.

pub mod compare;
pub mod plane_scenes;
pub mod room;
pub mod sensor;
