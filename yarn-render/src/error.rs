//! Why drawing or saving failed: [`RenderError`], the one error type of the
//! crate. This room only names failures; it must not know how they are
//! detected, nor anything of wgpu beyond the text of a device failure.

/// Why a frame could not be drawn or saved.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// Fewer than two nodes: there is no segment to draw.
    #[error("a yarn of {0} nodes has no segment to draw; give at least 2 positions")]
    TooFewNodes(usize),
    /// A position is NaN or infinite.
    #[error("position {index} is not finite ({value:?}); the simulation diverged or the input is bad")]
    NotFinite {
        /// Which node.
        index: usize,
        /// Its position.
        value: [f32; 3],
    },
    /// The image size is zero or beyond the device's texture limit.
    #[error("an image of {width}x{height} is outside 1..={limit} pixels a side")]
    BadSize {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
        /// The device's largest 2-D texture side.
        limit: u32,
    },
    /// The position buffer is smaller than one `vec4<f32>` (16 bytes) per
    /// node of the yarn drawn from it.
    #[error(
        "the position buffer holds {bytes} bytes, too few for {nodes} nodes at 16 bytes a node ({needed} bytes); \
         draw from the position buffer of the fabric the yarn was prepared from, or prepare the yarn from a \
         reference with as many nodes as the buffer holds"
    )]
    PositionBufferTooSmall {
        /// The buffer's size in bytes.
        bytes: u64,
        /// The bytes the yarn needs: 16 a node.
        needed: u64,
        /// The yarn's node count.
        nodes: usize,
    },
    /// The yarn spans do not cover the positions as a fabric's must
    /// ([`yarn_topology::validate_yarns`]).
    #[error("the yarns do not fit the positions: {0}")]
    Yarns(#[from] yarn_topology::TopologyError),
    /// The GPU failed.
    #[error("GPU error while rendering: {0}")]
    Device(String),
    /// The PNG could not be written.
    #[error("could not write the image: {0}")]
    Image(#[from] image::ImageError),
}
