//! Geometry helpers shared by the DAG builder (`mres-build`) and the validator (`mres-check`),
//! so that both measure distance, parts and edges the same way: a triangle BVH with exact
//! point-triangle distance ([`bvh`]), walks on a mesh towards a point ([`walk`]), connected parts
//! by union-find and triangle areas ([`parts`]) and the edge key by position ([`edges`]).
#![deny(missing_docs)]

pub mod bvh;
pub mod edges;
pub mod parts;
pub mod walk;
