// SPDX-License-Identifier: MIT
//! Simulation: scenes whose geometry is known exactly, rendered by CPU ray casting, for tests
//! and benchmarks with exact answers (and, later, seed 000's virtual depth sensor).

pub mod room;
