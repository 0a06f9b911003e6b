//! Named model presets: the model, its geometry and the gate that judges
//! it, chosen together by one flag (`--preset`).

use serde::Serialize;
use yarn_model::Params;
use yarn_topology::Geometry;

/// A model preset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// The default model ([`Params::default`], [`Geometry::default`]),
    /// judged at a certified rest.
    #[default]
    Default,
    /// The paper's model ([`Params::paper`], [`Geometry::paper`]) and its
    /// fixed-window gate, which reproduce its figures bit for bit.
    Paper,
}

impl Preset {
    /// The preset's model parameters.
    pub fn params(self) -> Params {
        match self {
            Preset::Default => Params::default(),
            Preset::Paper => Params::paper(),
        }
    }

    /// The preset's stitch geometry.
    pub fn geometry(self) -> Geometry {
        match self {
            Preset::Default => Geometry::default(),
            Preset::Paper => Geometry::paper(),
        }
    }
}
