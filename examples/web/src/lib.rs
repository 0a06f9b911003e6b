//! The yarnify browser demo: a knitted patch relaxing live on WebGPU, with
//! controls for the model and the knit-purl pattern, grab-and-drag,
//! unravelling and a dropped-stitch ladder.
//!
//! Everything the page does lives in [`Demo`], which is ordinary Rust over
//! the `yarn-backend-wgpu` backend and the `yarn-render` tube renderer, the
//! same WGSL files as natively; it runs (and is tested) on any wgpu
//! adapter. The WebAssembly entry point, compiled only for `wasm32`, wraps
//! it for JavaScript and draws into a canvas. Build the page with
//! `examples/web/build.sh`, then serve `examples/web/dist`.
//!
//! ```no_run
//! use yarn_backend_wgpu::Gpu;
//! use yarnify_web::{Demo, Settings};
//!
//! let gpu = Gpu::new()?;
//! let mut demo = Demo::new(gpu, yarnify_web::OFFSCREEN_FORMAT, Settings::default())?;
//! demo.set("friction", 0.5)?;
//! demo.set_pattern("rib-1x1")?;
//! demo.unravel(true)?;
//! demo.step()?;
//! println!("{} contacts alive", demo.status().alive);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![forbid(unsafe_code)]

mod demo;
#[cfg(target_arch = "wasm32")]
mod web;
#[cfg(target_arch = "wasm32")]
pub use web::{App, patterns, start};

pub use demo::{Demo, DemoError, OFFSCREEN_FORMAT, SETTINGS, Settings, Status, ladder_order, nearest, unravel_order};
