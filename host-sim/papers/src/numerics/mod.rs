//! The numerics shared by the slow-flow reproductions ([`crate::averaged`],
//! [`crate::paper001`]).

pub mod continuation;
pub mod linalg;

pub use continuation::{BranchPoint, ContinuationSettings, find_branches, folds, trace_branch};
pub use linalg::{eig4, fd_jacobian, newton4, quartic_roots, solve};
