//! The demo's actions on a real adapter (lavapipe in CI): it draws yarn,
//! a grab drags the fabric, unravelling and laddering release contacts, and
//! bad settings are refused with nothing changed. The same code runs in the
//! browser; `test/browser.test.mjs` drives it there.

use std::sync::Arc;

use yarn_backend_wgpu::{Gpu, testing, wgpu};
use yarnify_web::{Demo, DemoError, OFFSCREEN_FORMAT, Settings};

/// An 8x8 demo and the GPU context it runs on.
fn demo() -> Option<(Arc<Gpu>, Demo)> {
    match Gpu::new() {
        Ok(gpu) => {
            let settings = Settings { width: 8, height: 8, ..Settings::default() };
            Some((Arc::clone(&gpu), Demo::new(gpu, OFFSCREEN_FORMAT, settings).expect("demo")))
        }
        Err(e) => {
            testing::skip_without_adapter(&e);
            None
        }
    }
}

fn positions(demo: &Demo) -> Vec<[f32; 3]> {
    pollster::block_on(demo.positions().expect("read")).expect("positions").iter().map(|p| [p.x, p.y, p.z]).collect()
}

/// The fraction of pixels that are not background in a frame drawn by the
/// demo into an offscreen texture.
fn coverage(demo: &Demo, gpu: &Gpu) -> f64 {
    let (width, height) = (demo.view().width, demo.view().height);
    let texture = gpu.device().create_texture(&wgpu::TextureDescriptor {
        label: None,
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: OFFSCREEN_FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let staging = gpu.device().create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: u64::from(width * height * 4),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = gpu.device().create_command_encoder(&Default::default());
    demo.draw(&mut encoder, &texture.create_view(&Default::default())).expect("draw");
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(width * 4), rows_per_image: None },
        },
        texture.size(),
    );
    gpu.queue().submit([encoder.finish()]);
    let rgba = pollster::block_on(yarn_backend_wgpu::read_mapped(gpu.device(), &staging)).expect("frame");
    let frame = yarn_render::Frame { width, height, rgba };
    frame.coverage()
}

#[test]
fn the_demo_draws_grabs_unravels_and_ladders() {
    let Some((_, mut demo)) = demo() else { return };
    demo.resize(256, 192);
    for _ in 0..3 {
        demo.step().expect("step");
    }
    let status = demo.status();
    assert_eq!((status.nodes, status.substeps, status.frames), (8 * 8 * 8, 3 * 22, 3));

    // Grab the node drawn nearest the middle of the image and drag it up.
    let before = positions(&demo);
    let middle = before.len() / 2;
    let [x, y, _] = demo.yarn().project(demo.view(), before[middle]).expect("projects");
    let read = pollster::block_on(demo.positions().expect("read")).expect("positions");
    let node = demo.grab(&read, x, y).expect("grab").expect("a node under the cursor") as usize;
    demo.drag(x, y - 40.0).expect("drag");
    for _ in 0..10 {
        demo.step().expect("step");
    }
    assert_eq!(demo.status().grabbed, Some(node as u32));
    let after = positions(&demo);
    let moved = |i: usize| (0..3).map(|k| (after[i][k] - before[i][k]).powi(2)).sum::<f32>().sqrt();
    assert!(moved(node) > 1.0, "the grabbed node moved only {}", moved(node));
    // The snag travels: some other node moved too.
    let neighbours = (0..before.len()).filter(|&i| i != node && moved(i) > 0.1).count();
    assert!(neighbours > 10, "only {neighbours} other nodes followed the grab");
    demo.let_go().expect("let go");
    assert_eq!(demo.status().grabbed, None);

    // Unravel: contacts are released as frames pass.
    let contacts = demo.status().alive;
    demo.unravel(true).expect("unravel");
    for _ in 0..20 {
        demo.step().expect("step");
    }
    let status = demo.status();
    assert!(status.unravelling);
    assert_eq!(status.alive, contacts - 10, "one contact every second frame");
    let pulled = positions(&demo);
    let end = pulled.len() - 1;
    assert!(pulled[end][1] > after[end][1] + 1.0, "the loose end was not pulled up");

    // A ladder after a reset releases the middle column's contacts.
    demo.reset().expect("reset");
    assert_eq!(demo.status().alive, contacts);
    demo.ladder().expect("ladder");
    for _ in 0..8 {
        demo.step().expect("step");
    }
    assert!(demo.status().laddering);
    assert_eq!(demo.status().alive, contacts - 4);
}

#[test]
fn the_demo_draws_yarn() {
    let Some((gpu, mut demo)) = demo() else { return };
    demo.resize(256, 192); // 1,024-byte rows, as a texture copy needs
    demo.step().expect("step");
    let covered = coverage(&demo, &gpu);
    assert!(covered > 0.1 && covered < 0.95, "yarn covers {covered} of the frame");
    demo.zoom(3.0);
    assert!(coverage(&demo, &gpu) > covered, "zooming in should fill more of the frame");
}

#[test]
fn bad_settings_are_refused_and_change_nothing() {
    let Some((_, mut demo)) = demo() else { return };
    let settings = *demo.settings();
    assert!(matches!(demo.set("knitting", 1.0), Err(DemoError::UnknownSetting(name)) if name == "knitting"));
    assert!(matches!(demo.set("substeps", 0.0), Err(DemoError::OutOfRange { name: "substeps", .. })));
    assert!(matches!(demo.set("width", 1.5), Err(DemoError::OutOfRange { name: "width", .. })));
    assert!(matches!(demo.set("stretch", -5.0), Err(DemoError::Backend(_))));
    assert!(matches!(demo.set("damping", f64::NAN), Err(DemoError::Backend(_))));
    assert_eq!(*demo.settings(), settings);
    assert_eq!(demo.status().nodes, 8 * 8 * 8);
    demo.step().expect("still steps");

    demo.set("friction", 0.0).expect("friction off");
    demo.set("gravity", 1.0).expect("gravity on");
    demo.set("substeps", 5.0).expect("substeps");
    demo.set("height", 4.0).expect("a smaller patch");
    assert_eq!((demo.settings().substeps_per_frame, demo.status().nodes), (5, 8 * 4 * 8));
    demo.step().expect("step");
    assert_eq!(demo.status().substeps, 5);
}
