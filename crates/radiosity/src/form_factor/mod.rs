//! Stage 4a: form factors — how much of the energy leaving element `i` reaches element `j`.
//!
//! ```text
//! F_ij = 1/A_i ∫_{A_i} ∫_{A_j} cosθ_i cosθ_j / (π r²) · V(x, y) dA_y dA_x
//! ```
//!
//! (Goral, Torrance, Greenberg & Battaile 1984; Cohen & Wallace 1993, ch. 4). Every method
//! is a runtime choice ([`Method`]) and produces the same thing: the rows of `F` as a
//! [`SparseRows`] transport operator, with statistics.
//!
//! Methods:
//! - [`Method::PointSampled`] — the differential-area-to-polygon factor by the contour
//!   integral ([`kernel`]) at stratified points of the receiver, times the visible fraction
//!   from ray-sampled points of the source (Wallace, Elmquist & Haines 1989).

pub mod kernel;
mod point_sampled;

use std::str::FromStr;
use std::time::Instant;

use crate::accel::SceneRays;
use crate::mesh::{Mesh, Receivers};
use crate::scene::Scene;
use crate::transport::SparseRows;
use crate::{Error, Progress, Result};

/// A form-factor method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Point-to-polygon analytic factor times ray-sampled visibility (Wallace et al. 1989).
    PointSampled,
}

impl Method {
    /// Every method, in documentation order.
    pub const ALL: [Method; 1] = [Method::PointSampled];

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::PointSampled => "point-sampled",
        }
    }
}

impl FromStr for Method {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Method::ALL.iter().copied().find(|m| m.name() == s).ok_or_else(|| {
            let names: Vec<_> = Method::ALL.iter().map(|m| m.name()).collect();
            Error::Invalid(format!("unknown form-factor method '{s}' (known: {})", names.join(", ")))
        })
    }
}

/// Options shared by the methods (each uses those that apply to it).
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// The method.
    pub method: Method,
    /// Seed of every random choice; results do not depend on the thread count.
    pub seed: u64,
    /// Visibility rays per receiver point, as `n × n` stratified points on the source.
    pub visibility_samples: usize,
    /// Largest number of receiver points per side (`n × n`, at most
    /// [`crate::mesh::coverage::MAX_K`]), used for close pairs.
    pub max_receiver_samples: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options { method: Method::PointSampled, seed: 0, visibility_samples: 1, max_receiver_samples: 3 }
    }
}

/// What a form-factor computation did.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Stats {
    /// Method name.
    pub method: String,
    /// Element pairs with a non-zero factor.
    pub nonzeros: u64,
    /// Visibility rays cast.
    pub rays: u64,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// Computes the form-factor rows of all elements of `mesh`.
pub fn compute(
    scene: &Scene,
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    opts: &Options,
    progress: &dyn Progress,
) -> Result<(SparseRows, Stats)> {
    let t0 = Instant::now();
    let (rows, nrays) = match opts.method {
        Method::PointSampled => point_sampled::compute(scene, mesh, rays, receivers, opts, progress)?,
    };
    let stats = Stats {
        method: opts.method.name().to_string(),
        nonzeros: rows.nnz() as u64,
        rays: nrays,
        seconds: t0.elapsed().as_secs_f64(),
    };
    Ok((rows, stats))
}
