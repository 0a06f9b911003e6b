//! The demo's actions on a real adapter (lavapipe in CI): it draws yarn,
//! a grab drags the fabric, unravelling and laddering release contacts, a
//! pattern rebuilds the patch in its stitches, and bad settings are refused
//! with nothing changed. The same code runs in the
//! browser; `test/browser.test.mjs` drives it there.

use std::sync::Arc;

use yarn_backend_wgpu::{Gpu, Raised, testing, wgpu};
use yarn_topology::{Fabric, Front, Pattern};
use yarnify_web::{Demo, DemoError, OFFSCREEN_FORMAT, SETTINGS, Settings};

/// Nodes in a `w` x `h` patch of the default (interlooped) geometry: 24 a
/// loop, the sinker that closes each row, and 4 in each turn between rows.
fn nodes(w: usize, h: usize) -> usize {
    h * (24 * w + 1) + 4 * (h - 1)
}

/// Contacts in a `w` x `h` patch: the four crossings of each loop with the
/// loop drawn through it.
fn contacts(w: usize, h: usize) -> usize {
    4 * w * (h - 1)
}

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

fn distance(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt()
}

fn steps(demo: &mut Demo, frames: usize) {
    for _ in 0..frames {
        demo.step().expect("step");
    }
}

/// How far up the grab test drags, in pixels.
const DRAG: f32 = 40.0;

/// A grab holds the grabbed node under the cursor. Measured against the
/// same frames from the same start without the grab, so that what free
/// relaxation moves anyway does not count: the grabbed node ends up where
/// the cursor is and well away from where it would have been, while the
/// far side of the patch hardly notices.
#[test]
fn a_grab_carries_the_grabbed_node_to_the_cursor() {
    let Some((_, mut demo)) = demo() else { return };
    demo.resize(256, 192);
    steps(&mut demo, 3);
    let start = positions(&demo);
    steps(&mut demo, 10);
    let free = positions(&demo);

    demo.reset().expect("reset");
    steps(&mut demo, 3);
    // Grab the node drawn nearest the middle of the image and drag it up.
    let middle = start.len() / 2;
    let [x, y, depth] = demo.yarn().project(demo.view(), start[middle]).expect("projects");
    let read = pollster::block_on(demo.positions().expect("read")).expect("positions");
    let node = demo.grab(&read, x, y).expect("grab").expect("a node under the cursor") as usize;
    demo.drag(x, y - DRAG).expect("drag");
    steps(&mut demo, 10);
    assert_eq!(demo.status().grabbed, Some(node as u32));
    let held = positions(&demo);

    // Drawn under the cursor.
    let [hx, hy, _] = demo.yarn().project(demo.view(), held[node]).expect("projects");
    assert!(
        (hx - x).abs() < 0.5 && (hy - (y - DRAG)).abs() < 0.5,
        "node {node} is drawn at ({hx}, {hy}), the cursor is at ({x}, {})",
        y - DRAG
    );
    // Moved by the drag, not by relaxation: the drag spans `reach` in the
    // grab's plane, and the node ends up most of that from its free self.
    let reach = distance(
        demo.yarn().unproject(demo.view(), x, y, depth),
        demo.yarn().unproject(demo.view(), x, y - DRAG, depth),
    );
    let off = |i: usize| distance(held[i], free[i]);
    // The quarter of the nodes farthest from the grabbed one.
    let mut by_distance: Vec<usize> = (0..start.len()).collect();
    by_distance.sort_by(|&i, &j| distance(start[i], start[node]).total_cmp(&distance(start[j], start[node])));
    let far = &by_distance[3 * start.len() / 4..];
    let far_off = far.iter().map(|&i| off(i)).fold(0.0, f32::max);
    println!(
        "the grab moved node {node} {:.3} from its free self (the drag spans {reach:.3}); the far quarter at most {far_off:.4}",
        off(node)
    );
    assert!(off(node) > 0.8 * reach, "the grabbed node is {} from its free self; the drag spans {reach}", off(node));
    assert!(far_off < 0.1 * off(node), "the far side moved {far_off}, the grabbed node {}", off(node));
    demo.let_go().expect("let go");
    assert_eq!(demo.status().grabbed, None);
}

#[test]
fn the_demo_steps_unravels_and_ladders() {
    let Some((_, mut demo)) = demo() else { return };
    steps(&mut demo, 3);
    let status = demo.status();
    assert_eq!(
        (status.nodes, status.contacts, status.substeps, status.frames),
        (nodes(8, 8), contacts(8, 8), 3 * 22, 3)
    );
    let before = positions(&demo);

    // Unravel: contacts are released as frames pass.
    let contacts = demo.status().alive;
    demo.unravel(true).expect("unravel");
    steps(&mut demo, 20);
    let status = demo.status();
    assert!(status.unravelling);
    assert_eq!(status.alive, contacts - 10, "one contact every second frame");
    let pulled = positions(&demo);
    let end = pulled.len() - 1;
    assert!(pulled[end][1] > before[end][1] + 1.0, "the loose end was not pulled up");

    // A ladder after a reset releases the middle column's contacts.
    demo.reset().expect("reset");
    assert_eq!(demo.status().alive, contacts);
    demo.ladder().expect("ladder");
    steps(&mut demo, 8);
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

/// Each refusal names the setting, the value and the values it takes, and
/// leaves the demo as it was: the settings, the patch and its motion so far.
#[test]
fn bad_settings_are_refused_by_name_and_change_nothing() {
    let Some((_, mut demo)) = demo() else { return };
    steps(&mut demo, 2);
    let (settings, status, moved) = (*demo.settings(), demo.status(), positions(&demo));
    let mut refused = |name: &str, value: f64| demo.set(name, value).expect_err(name).to_string();
    assert_eq!(
        refused("knitting", 1.0),
        "unknown setting `knitting`; the settings are: stretch, bend, curl, contact, friction, self-contact, damping, gravity, floor, \
         substeps, width, height"
    );
    assert_eq!(refused("substeps", 0.0), "substeps = 0 is outside the whole numbers 1..=500");
    assert_eq!(refused("substeps", 501.0), "substeps = 501 is outside the whole numbers 1..=500");
    assert_eq!(refused("width", 1.5), "width = 1.5 is outside the whole numbers 2..=128");
    assert_eq!(refused("height", 129.0), "height = 129 is outside the whole numbers 2..=128");
    assert_eq!(refused("stretch", -5.0), "parameter `stretch_stiffness` is -5; it must be greater than 0");
    assert_eq!(refused("curl", 1.5), "parameter `rest_curl` is 1.5; it must be between 0 and 1");
    assert_eq!(refused("damping", f64::NAN), "parameter `damping` is NaN; it must be a finite number");
    assert_eq!(
        demo.set_pattern("nope").expect_err("nope").to_string(),
        "unknown pattern `nope`; use one of: stockinette, reverse-stockinette, garter, rib-1x1, rib-2x2, seed"
    );
    assert_eq!(
        demo.set("pattern", 1.0).expect_err("pattern").to_string(),
        "the pattern is a name, not a number: set it with set_pattern, to one of: \
         stockinette, reverse-stockinette, garter, rib-1x1, rib-2x2, seed"
    );
    assert!(matches!(demo.setting("pattern"), Err(DemoError::PatternIsAName)));
    assert!(matches!(demo.set("width", 1.5), Err(DemoError::OutOfRange { name: "width", .. })));
    assert!(matches!(demo.set("stretch", -5.0), Err(DemoError::Backend(_))));
    assert_eq!(*demo.settings(), settings);
    // Not reloaded, not stepped: the same patch where it was.
    assert_eq!(demo.status(), status);
    assert_eq!(positions(&demo), moved);
    steps(&mut demo, 1);
    assert_eq!(demo.status().substeps, status.substeps + 22, "still steps");
}

/// The face order of the four crossings between the loops of rows 0 and 1
/// in `column`, in contact order: which strand lies toward the face at each.
fn fronts(fabric: &Fabric, column: usize) -> Vec<Option<Front>> {
    let n = fabric.nodes_per_loop().expect("a grid");
    let loop_nodes =
        |row| (1..n).filter_map(|p| fabric.stitch_node(column, row, p)).map(|i| i as u32).collect::<Vec<_>>();
    let (below, above) = (loop_nodes(0), loop_nodes(1));
    let fronts: Vec<_> =
        fabric.contacts().iter().filter(|c| below.contains(&c.a) && above.contains(&c.b)).map(|c| c.front).collect();
    assert_eq!(fronts.len(), 4, "four crossings join the loops of rows 0 and 1 in column {column}");
    fronts
}

/// Each pattern rebuilds the patch from its own chart: the status counts
/// its purl stitches, and in a 1x1 rib the strand in front flips at every
/// crossing of a purl column, against the knit column beside it.
#[test]
fn a_pattern_rebuilds_the_patch_in_its_stitches() {
    let Some((_, mut demo)) = demo() else { return };
    steps(&mut demo, 2);
    // 8x8: every stitch purl in reverse stockinette, half of them in the
    // other patterns but plain stockinette.
    for (pattern, purls) in Pattern::ALL.into_iter().zip([0, 64, 32, 32, 32, 32]) {
        let name = pattern.name();
        demo.set_pattern(name).expect(name);
        assert_eq!(demo.settings().pattern, pattern);
        let status = demo.status();
        assert_eq!((status.pattern, status.purls), (name, purls));
        // A fresh patch: the same yarn and crossings, from the start.
        assert_eq!(
            (status.nodes, status.contacts, status.alive, status.frames, status.substeps),
            (nodes(8, 8), contacts(8, 8), contacts(8, 8), 0, 0),
            "{pattern}"
        );
    }
    demo.set_pattern("stockinette").expect("stockinette");
    let knit = fronts(demo.fabric(), 0);
    assert!(knit.iter().all(Option::is_some), "every crossing has a strand in front: {knit:?}");
    assert_eq!(fronts(demo.fabric(), 1), knit, "stockinette is knit in every column");
    let flipped: Vec<_> = knit.iter().map(|f| f.map(|f| if f == Front::A { Front::B } else { Front::A })).collect();
    demo.set_pattern("rib-1x1").expect("rib-1x1");
    assert_eq!(fronts(demo.fabric(), 0), knit, "column 0 of a 1x1 rib is knit");
    assert_eq!(fronts(demo.fabric(), 1), flipped, "column 1 of a 1x1 rib is purl");
    steps(&mut demo, 2);
    assert_eq!(demo.status().substeps, 2 * 22, "the rib steps");
    // A reset and a size change keep the pattern.
    demo.reset().expect("reset");
    assert_eq!(demo.status().purls, 32);
    demo.set("width", 6.0).expect("width");
    assert_eq!((demo.status().pattern, demo.status().purls, demo.status().nodes), ("rib-1x1", 3 * 8, nodes(6, 8)));
}

/// Every setting named in [`SETTINGS`] takes a value and reads it back, and
/// the ones with a visible effect have it.
#[test]
fn every_setting_takes_effect_and_reads_back() {
    let Some((_, mut demo)) = demo() else { return };
    let values = [
        ("stretch", 500.0),
        ("bend", 2.5),
        ("curl", 0.2),
        ("contact", 400.0),
        ("friction", 0.0),
        ("self-contact", 800.0),
        ("damping", 20.0),
        ("gravity", 1.0),
        ("floor", 1.0),
        ("substeps", 5.0),
        ("width", 6.0),
        ("height", 4.0),
    ];
    let names: Vec<&str> = values.iter().map(|(name, _)| *name).collect();
    assert_eq!(names, SETTINGS.split(", ").collect::<Vec<_>>(), "a setting without a value here");
    for (name, value) in values {
        assert_ne!(demo.setting(name).expect(name), value, "{name} is {value} already");
        demo.set(name, value).expect(name);
        assert_eq!(demo.setting(name).expect(name), value, "{name}");
    }
    assert!(matches!(demo.setting("knitting"), Err(DemoError::UnknownSetting(_))));
    assert_eq!(demo.settings().params.self_contact_stiffness, 800.0);
    demo.set("floor", 0.0).expect("floor off");
    let settings = demo.settings();
    assert_eq!((settings.params.rest_curl, settings.params.gravity), (0.2, 9.81));
    assert_eq!(demo.status().nodes, nodes(6, 4));
    // Gravity holds the top row, and the rest hangs lower than the same
    // frames without gravity leave it; five substeps a frame.
    let rest = positions(&demo);
    steps(&mut demo, 40);
    assert_eq!(demo.status().substeps, 40 * 5);
    let hung = positions(&demo);
    demo.set("gravity", 0.0).expect("gravity off");
    demo.reset().expect("reset");
    steps(&mut demo, 40);
    let free = positions(&demo);
    let (low, high) =
        rest.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(low, high), p| (low.min(p[1]), high.max(p[1])));
    let rest = &rest;
    let row = |y: f32| (0..rest.len()).filter(move |&i| (rest[i][1] - y).abs() < 0.5);
    let sag = row(low).map(|i| free[i][1] - hung[i][1]).sum::<f32>() / row(low).count() as f32;
    let top = row(high).map(|i| distance(hung[i], rest[i])).fold(0.0, f32::max);
    println!("in 40 frames gravity hung the bottom row {sag:.3} lower on average; the top row moved at most {top:.5}");
    assert!(sag > 0.02, "gravity hung the bottom row only {sag} lower");
    assert!(top < 0.1 * sag, "the top row, held, moved {top}");
}

/// The floor: checked, the patch is laid flat three yarn radii above it and
/// falls under gravity, nothing held, with self-contact on, until it lies
/// on it; no node goes under it and no two segments of yarn come closer
/// than 1.9 r. Unchecked, the patch stands as knitted again.
#[test]
fn a_patch_dropped_on_the_floor_lands_on_it_and_never_passes_it() {
    let Some((_, mut demo)) = demo() else { return };
    demo.set("width", 4.0).expect("width");
    demo.set("height", 4.0).expect("height");
    demo.set("substeps", 40.0).expect("substeps");
    demo.set("floor", 1.0).expect("floor on");
    let status = demo.status();
    assert!(status.floor && !status.unravelling);
    assert_eq!((demo.settings().params.gravity, demo.settings().params.self_contact_stiffness), (9.81, 1600.0));
    let r = demo.fabric().yarn_radius() as f32;
    let lowest = |p: &[[f32; 3]]| p.iter().map(|p| p[1]).fold(f32::INFINITY, f32::min);
    let start = positions(&demo);
    assert!((lowest(&start) - 3.0 * r).abs() < 1e-4, "laid {} above the floor", lowest(&start));
    let model = yarn_model::Model::<f32>::new(demo.fabric(), &demo.settings().params).expect("model");
    let mut low = f32::INFINITY;
    let mut closest = f64::INFINITY;
    for _ in 0..10 {
        steps(&mut demo, 10);
        let at = positions(&demo);
        low = low.min(lowest(&at));
        let x: Vec<yarn_model::V3<f32>> = at.iter().map(|p| yarn_model::V3::new(p[0], p[1], p[2])).collect();
        if let Some((d, _)) = yarn_model::self_contact::closest_approach(&model, &x, 4.0) {
            closest = closest.min(d);
        }
    }
    let end = lowest(&positions(&demo));
    println!(
        "the lowest node fell from {:.3} to {end:.3} ({low:.3} at its lowest); closest approach {closest:.3} r",
        lowest(&start)
    );
    assert!(end < 1.5 * r && low > 0.5 * r, "it ended {end} above the floor, and went down to {low}");
    assert!(closest > 1.9, "two segments came {closest} r apart");
    demo.set("floor", 0.0).expect("floor off");
    assert!(!demo.status().floor);
    assert_eq!(positions(&demo)[0], start_of(&demo));
}

/// Node 0 as knitted.
fn start_of(demo: &Demo) -> [f32; 3] {
    let p = demo.fabric().positions()[0];
    [p.x as f32, p.y as f32, p.z as f32]
}

/// What the GPU raised, acted on as the browser does twice a second: a
/// crowded list grows and the status says so; a divergence starts the
/// patch again and says so. Natively the advance itself waits for the
/// status, so the read finds nothing and changes nothing.
#[test]
fn what_the_gpu_raised_grows_the_lists_or_starts_again() {
    let Some((_, mut demo)) = demo() else { return };
    demo.set("self-contact", 1600.0).expect("self-contact on");
    steps(&mut demo, 3);
    let raised = pollster::block_on(demo.read_raised().expect("read")).expect("raised");
    assert!(raised.is_clear(), "{raised:?}");
    let before = demo.status();
    demo.settle(raised).expect("settle");
    assert_eq!(demo.status(), before, "settling nothing changed the demo");

    let slots = before.slots;
    let crowd = Raised { first: 30, end: 60, crowded: Some(slots + 1), ..Raised::default() };
    demo.settle(crowd).expect("grow");
    let status = demo.status();
    assert_eq!(status.slots, 2 * slots);
    let said = status.raised.expect("the growth is reported");
    assert!(said.contains(&format!("{}", slots + 1)) && said.contains(&format!("grew to {}", 2 * slots)), "{said}");
    assert_eq!(status.substeps, before.substeps, "growing the lists started the patch again");
    demo.settle(crowd).expect("the same crowd again");
    assert_eq!(demo.status().slots, 2 * slots, "lists that hold the crowd grew again");

    demo.settle(Raised { first: 60, end: 90, diverged: true, ..Raised::default() }).expect("start again");
    let status = demo.status();
    assert_eq!((status.substeps, status.frames), (0, 0), "the diverged patch was kept");
    let said = status.raised.expect("the divergence is reported");
    assert!(said.contains("diverged during substeps 60..90"), "{said}");
    assert_eq!(positions(&demo)[0], start_of(&demo));
}
