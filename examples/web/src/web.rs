//! The WebAssembly entry point: [`Demo`] drawing into a canvas through the
//! browser's WebGPU, with its actions exported to JavaScript (`www/main.js`).

use std::cell::RefCell;
use std::rc::Rc;
use std::sync::Arc;

use wasm_bindgen::prelude::*;
use yarn_backend_wgpu::{Gpu, wgpu};
use yarn_topology::Pattern;

use crate::{Demo, Settings};

/// The demo in a canvas.
#[wasm_bindgen]
#[derive(Debug)]
pub struct App {
    gpu: Arc<Gpu>,
    /// Shared with grabs in flight, which finish in a later task.
    demo: Rc<RefCell<Demo>>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    /// The canvas format's sRGB view, which the renderer draws into.
    view_format: wgpu::TextureFormat,
}

/// Open the browser's WebGPU adapter and start the default patch in
/// `canvas`.
///
/// # Errors
/// No WebGPU adapter, or a device or canvas that refuses.
#[wasm_bindgen]
pub async fn start(canvas: web_sys::HtmlCanvasElement) -> Result<App, JsError> {
    console_error_panic_hook::set_once();
    let gpu = Gpu::new_async().await?;
    let (width, height) = (canvas.width().max(1), canvas.height().max(1));
    let surface = gpu.instance().create_surface(wgpu::SurfaceTarget::Canvas(canvas))?;
    let mut config = surface
        .get_default_config(gpu.wgpu_adapter(), width, height)
        .ok_or_else(|| JsError::new("the canvas cannot be drawn into by this adapter"))?;
    let view_format = config.format.add_srgb_suffix();
    if view_format != config.format {
        config.view_formats.push(view_format);
    }
    surface.configure(gpu.device(), &config);
    let mut demo = Demo::new(Arc::clone(&gpu), view_format, Settings::default())?;
    demo.resize(width, height);
    Ok(App { gpu, demo: Rc::new(RefCell::new(demo)), surface, config, view_format })
}

/// The names of every pattern the demo knits, for the page's selector.
#[wasm_bindgen]
pub fn patterns() -> Vec<String> {
    Pattern::ALL.iter().map(|pattern| pattern.name().to_owned()).collect()
}

#[wasm_bindgen]
impl App {
    /// Step one frame (the scheduled releases, then the substeps) and draw
    /// it. Nothing is read back.
    ///
    /// # Errors
    /// A device failure.
    pub fn frame(&self) -> Result<(), JsError> {
        let mut demo = self.demo.borrow_mut();
        demo.step()?;
        let texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            // Hidden or being resized: skip drawing this frame.
            _ => return Ok(()),
        };
        let view = texture
            .texture
            .create_view(&wgpu::TextureViewDescriptor { format: Some(self.view_format), ..Default::default() });
        let mut encoder = self.gpu.device().create_command_encoder(&Default::default());
        demo.draw(&mut encoder, &view)?;
        self.gpu.queue().submit([encoder.finish()]);
        self.gpu.queue().present(texture);
        Ok(())
    }

    /// The canvas's new size in pixels.
    pub fn resize(&mut self, width: u32, height: u32) {
        (self.config.width, self.config.height) = (width.max(1), height.max(1));
        self.surface.configure(self.gpu.device(), &self.config);
        self.demo.borrow_mut().resize(self.config.width, self.config.height);
    }

    /// Change a setting by name; see [`Demo::set`].
    ///
    /// # Errors
    /// An unknown name or a refused value; nothing changed.
    pub fn set(&self, name: &str, value: f64) -> Result<(), JsError> {
        Ok(self.demo.borrow_mut().set(name, value)?)
    }

    /// The current value of a setting by name; see [`Demo::setting`].
    ///
    /// # Errors
    /// An unknown name.
    pub fn setting(&self, name: &str) -> Result<f64, JsError> {
        Ok(self.demo.borrow().setting(name)?)
    }

    /// Knit the patch in the pattern named `name`; see
    /// [`Demo::set_pattern`].
    ///
    /// # Errors
    /// A name that is no pattern; nothing changed.
    pub fn set_pattern(&self, name: &str) -> Result<(), JsError> {
        Ok(self.demo.borrow_mut().set_pattern(name)?)
    }

    /// The name of the pattern the patch is knitted in.
    pub fn pattern(&self) -> String {
        self.demo.borrow().settings().pattern.name().to_owned()
    }

    /// Start again from the flat patch.
    ///
    /// # Errors
    /// A device failure.
    pub fn reset(&self) -> Result<(), JsError> {
        Ok(self.demo.borrow_mut().reset()?)
    }

    /// Grab the node nearest pixel (`x`, `y`): the positions are read back
    /// now, the only read-back the page makes. Resolves to the node's index,
    /// or -1 when nothing is near.
    pub fn grab(&self, x: f32, y: f32) -> js_sys::Promise {
        let read = self.demo.borrow().positions();
        let demo = Rc::clone(&self.demo);
        wasm_bindgen_futures::future_to_promise(async move {
            let positions = read.map_err(error)?.await.map_err(error)?;
            let node = demo.borrow_mut().grab(&positions, x, y).map_err(error)?;
            Ok(JsValue::from_f64(node.map_or(-1.0, f64::from)))
        })
    }

    /// Drag the grabbed node under pixel (`x`, `y`).
    ///
    /// # Errors
    /// A device failure.
    pub fn drag(&self, x: f32, y: f32) -> Result<(), JsError> {
        Ok(self.demo.borrow_mut().drag(x, y)?)
    }

    /// Let go of the grabbed node.
    ///
    /// # Errors
    /// A device failure.
    pub fn let_go(&self) -> Result<(), JsError> {
        Ok(self.demo.borrow_mut().let_go()?)
    }

    /// Start or stop unravelling from the loose end.
    ///
    /// # Errors
    /// A device failure.
    pub fn unravel(&self, on: bool) -> Result<(), JsError> {
        Ok(self.demo.borrow_mut().unravel(on)?)
    }

    /// Drop a stitch at the top of the middle column and let it ladder.
    ///
    /// # Errors
    /// A device failure.
    pub fn ladder(&self) -> Result<(), JsError> {
        Ok(self.demo.borrow_mut().ladder()?)
    }

    /// Turn the camera by `orbit` and `elevation` radians.
    pub fn orbit(&self, orbit: f32, elevation: f32) {
        self.demo.borrow_mut().orbit(orbit, elevation);
    }

    /// Zoom in by `factor`.
    pub fn zoom(&self, factor: f32) {
        self.demo.borrow_mut().zoom(factor);
    }

    /// Where the point (`x`, `y`, `z`) is drawn on the canvas: pixel x, y
    /// and depth as a `Float32Array`, or `undefined` behind the camera. For
    /// tests and tools, to find a node read back with [`App::positions`]
    /// on screen.
    pub fn project(&self, x: f32, y: f32, z: f32) -> Option<Vec<f32>> {
        let demo = self.demo.borrow();
        demo.yarn().project(demo.view(), [x, y, z]).map(Vec::from)
    }

    /// The status as JSON: adapter, pattern, purls, nodes, contacts,
    /// alive, substeps, frames, grabbed, unravelling, laddering, floor,
    /// slots, raised ([`crate::Status`]).
    pub fn status(&self) -> String {
        serde_json::to_string(&self.demo.borrow().status()).unwrap_or_default()
    }

    /// Read what the GPU raised since the last look, without blocking, and
    /// act on it ([`Demo::settle`]): grow crowded self-contact lists, or
    /// start again after a divergence. The page calls it twice a second;
    /// the status says what it did.
    pub fn check(&self) -> js_sys::Promise {
        let read = self.demo.borrow_mut().read_raised();
        let demo = Rc::clone(&self.demo);
        wasm_bindgen_futures::future_to_promise(async move {
            let raised = read.map_err(error)?.await.map_err(error)?;
            demo.borrow_mut().settle(raised).map_err(error)?;
            Ok(JsValue::UNDEFINED)
        })
    }

    /// The current positions as a flat `Float32Array` (x, y, z per node),
    /// read back without blocking. For tests and tools; the page itself
    /// reads back only to grab.
    pub fn positions(&self) -> js_sys::Promise {
        let read = self.demo.borrow().positions();
        wasm_bindgen_futures::future_to_promise(async move {
            let positions = read.map_err(error)?.await.map_err(error)?;
            let flat: Vec<f32> = positions.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
            Ok(js_sys::Float32Array::from(flat.as_slice()).into())
        })
    }
}

/// An error as a JavaScript `Error`.
fn error(e: impl std::error::Error) -> JsValue {
    JsError::new(&e.to_string()).into()
}
