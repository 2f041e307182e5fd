//! pcrnet firmware example: register a stored point cloud against the
//! model's template, with the int8 model used in place from flash and all
//! working memory in statics. Prints the pose, its residual and whether it
//! is reliable, and the instruction count over semihosting.
//!
//! It acts on the confidence: a pose that is not reliable is retried with
//! every flip hypothesis the blob stores; if that is still not reliable, the
//! example reports that it has no pose to act on (a real application would
//! keep its last good pose or ask for another view).
//!
//! Then it finds the object in a raw depth frame (224 x 172, millimetres:
//! the template on a table beside two blocks, drawn on the device by
//! `pcrnet_core::testing::scene::harness_frame` where a depth sensor's
//! driver would fill the buffer) and registers it with `Int8Model::locate`:
//! the plane taken out, clusters of the object's size registered by a yaw
//! sweep about the plane's normal and checked against the frame. The QEMU
//! harness checks that very call bit for bit against the host. Then it
//! follows the object into the next frame (`Int8Model::follow`: here the
//! same frame) from the pose and plane it found, as a stream would.
//!
//! Memory (embedded default architecture, tile 8): model blob in flash
//! (~230 KB), scratch 4,355 B and the cloud 12 B/point in RAM; for the
//! frame, its 77 KB of pixels, 9.6 KB of labels and 6 KB of points; stack
//! and totals are measured by `cargo xtask size` / `cargo xtask qemu-test`.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::debug;
#[cfg(feature = "defmt")]
use defmt_semihosting as _;
use panic_semihosting as _;
use pcrnet_core::{Int8Model, MAX_TILE, Options, Registration, int8_scratch_len};
use pcrnet_firmware_example::{icount::Counter, stack};

/// Text over semihosting, or defmt frames with the `defmt` feature.
#[cfg(not(feature = "defmt"))]
macro_rules! log {
    ($($t:tt)*) => { cortex_m_semihosting::hprintln!($($t)*) };
}
#[cfg(feature = "defmt")]
macro_rules! log {
    ($($t:tt)*) => { defmt::println!($($t)*) };
}

/// The int8 model, used in place from flash (no alignment needed).
static MODEL: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");
/// A stored source cloud: x, y, z as f32 little-endian per point. On a real
/// device a sensor driver fills the cloud buffer instead.
const SOURCE: &[u8] = include_bytes!("../../models/embedded-default-source.f32");
const POINTS: usize = SOURCE.len() / 12;
/// Scratch for the model's architecture at the largest tile; `Int8Model::load`
/// checks it is big enough.
const SCRATCH: usize = int8_scratch_len(&[32, 64, 128, 256], &[256, 128, 64], MAX_TILE);

#[entry]
fn main() -> ! {
    // cortex-m-rt makes these `&'static mut`: RAM owned by `main`, no heap.
    static mut SCRATCH_BUF: [i8; SCRATCH] = [0; SCRATCH];
    static mut CLOUD: [[f32; 3]; POINTS] = [[0.0; 3]; POINTS];

    stack::paint();
    let Some(core) = cortex_m::Peripherals::take() else {
        log!("core peripherals already taken");
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    };
    let counter = Counter::start(core.SYST);

    for (p, bytes) in CLOUD.iter_mut().zip(SOURCE.chunks_exact(12)) {
        for (x, b) in p.iter_mut().zip(bytes.chunks_exact(4)) {
            *x = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
    }

    // Stack of each phase, measured by painting (see `stack`).
    let baseline = stack::paint();
    let loaded = Int8Model::load(MODEL, SCRATCH_BUF);
    let load_stack = stack::used_below(baseline);
    let code = match loaded {
        Ok(model) => {
            log!("points: {}", POINTS);
            // The recommended pipeline: one network pass, 4 starting poses,
            // ICP against the template's points, residual.
            let options = Options::default();
            let baseline = stack::paint();
            let start = counter.instructions();
            let mut result = model.register(CLOUD, &options, SCRATCH_BUF);
            log!("instructions: {}", counter.instructions() - start);
            let register_stack = stack::used_below(baseline);
            if let Ok(r) = &result {
                report(r);
                if !r.reliable {
                    // Act on the confidence: try every stored turn before giving up.
                    let all = Options {
                        hypotheses: usize::MAX,
                        ..options
                    };
                    log!("not reliable: retrying with every flip hypothesis");
                    let start = counter.instructions();
                    result = model.register(CLOUD, &all, SCRATCH_BUF);
                    log!("instructions: {}", counter.instructions() - start);
                    if let Ok(r) = &result {
                        report(r);
                    }
                }
            }
            log!(
                "stack: load {} B, register {} B, below main's {} B",
                load_stack,
                register_stack,
                stack::in_use(baseline)
            );
            locate(&model, &counter, SCRATCH_BUF);
            seen_from_above(&model, &counter, CLOUD, SCRATCH_BUF);
            match result {
                Ok(r) if r.reliable => {
                    log!("pose reliable: acting on it");
                    debug::EXIT_SUCCESS
                }
                Ok(_) => {
                    log!("no reliable pose: keeping the last good one");
                    debug::EXIT_SUCCESS
                }
                Err(e) => {
                    log!("registration failed: {:?}", e);
                    debug::EXIT_FAILURE
                }
            }
        }
        Err(e) => {
            log!("model rejected: {:?}", e);
            debug::EXIT_FAILURE
        }
    };
    debug::exit(code);
    // Not reached under QEMU (semihosting exit ends the emulator).
    loop {
        cortex_m::asm::wfi();
    }
}

/// Finds the model's object in a depth frame and prints its pose, the
/// check against the frame and the cost.
fn locate(model: &Int8Model, counter: &Counter, scratch: &mut [i8]) {
    use pcrnet_core::scene::{self, SceneOptions};
    use pcrnet_core::testing::scene as frame;
    const W: usize = frame::HARNESS_WIDTH;
    const H: usize = frame::HARNESS_HEIGHT;
    const STEP: usize = 4;
    static mut DEPTH: [u16; W * H] = [0; W * H];
    static mut TEMPLATE: [[f32; 3]; 512] = [[0.0; 3]; 512];
    static mut LABELS: [u16; scene::labels_len(W, H, STEP)] = [0; scene::labels_len(W, H, STEP)];
    static mut POINTS: [[f32; 3]; 512] = [[0.0; 3]; 512];
    // SAFETY: `locate` runs once, on one thread, and is the only code
    // naming these buffers.
    let (depth, template, labels, points) = unsafe {
        (
            &mut *core::ptr::addr_of_mut!(DEPTH),
            &mut *core::ptr::addr_of_mut!(TEMPLATE),
            &mut *core::ptr::addr_of_mut!(LABELS),
            &mut *core::ptr::addr_of_mut!(POINTS),
        )
    };
    // A depth sensor's driver would fill `depth`; here the frame is drawn.
    if let Err(e) = frame::harness_frame(model, template, depth) {
        log!("frame: {:?}", e);
        return;
    }
    let image = match frame::harness_image(depth) {
        Ok(image) => image,
        Err(e) => {
            log!("frame: {:?}", e);
            return;
        }
    };
    // The template's z axis points away from the table it stands on.
    let options = SceneOptions {
        step: STEP,
        up: Some([0.0, 0.0, 1.0]),
        ..SceneOptions::for_object(model.object_radius())
    };
    let baseline = stack::paint();
    let start = counter.instructions();
    let located = model.locate(
        &image,
        &options,
        3,
        &Options::default(),
        labels,
        points,
        scratch,
    );
    log!(
        "locate in a {}x{} depth frame: {} instructions, stack {} B",
        W,
        H,
        counter.instructions() - start,
        stack::used_below(baseline)
    );
    match located {
        Ok(l) => match l.best {
            Some(best) => {
                log!(
                    "cluster {} of {} kept, {} registered; check: {} points seen, {} in free space",
                    best.cluster,
                    l.segmentation.clusters.kept.len(),
                    l.tried.len(),
                    best.verification.map_or(0, |v| v.supported),
                    best.verification.map_or(0, |v| v.violations)
                );
                report(&best.registration);
                log!("object in the frame reliable: {}", best.reliable);
                let (pose, plane) = (best.registration.pose, l.segmentation.plane);
                let start = counter.instructions();
                let next = model.follow(
                    &image,
                    &options,
                    &pose,
                    plane,
                    &Options::default(),
                    labels,
                    points,
                    scratch,
                );
                let spent = counter.instructions() - start;
                match next.map(|n| n.best.is_some_and(|b| b.reliable)) {
                    Ok(reliable) => log!(
                        "followed into the next frame: {} instructions, reliable: {}",
                        spent,
                        reliable
                    ),
                    Err(e) => log!("follow failed: {:?}", e),
                }
            }
            None => log!("no cluster of the object's size in the frame"),
        },
        Err(e) => log!("locate failed: {:?}", e),
    }
}

/// Registers the cloud as a view from a sensor above it, checked against
/// that view (`Int8Model::register_view`): a cut single view whose sensor
/// position is known (the origin, for points in a camera's frame) gets a
/// verdict that a fragment or a pose slid onto the wrong side cannot pass.
fn seen_from_above(model: &Int8Model, counter: &Counter, cloud: &[[f32; 3]], scratch: &mut [i8]) {
    use pcrnet_core::scene::view;
    static mut VIEW: [f32; view::buffer_len(32)] = [0.0; view::buffer_len(32)];
    // SAFETY: called once, on one thread; the only code naming VIEW.
    let buffer = unsafe { &mut *core::ptr::addr_of_mut!(VIEW) };
    // Three radii above the cloud's centre (a driver knows its sensor's place).
    let viewpoint = pcrnet_core::testing::harness_viewpoint(cloud);
    let start = counter.instructions();
    let seen = model.register_view(cloud, viewpoint, &Options::default(), scratch, buffer);
    log!(
        "registration seen from {:?}: {} instructions",
        viewpoint,
        counter.instructions() - start
    );
    match seen {
        Ok(v) => {
            log!(
                "view: {} template points on the seen surface, {} where the sensor saw past the object, {} behind it",
                v.view.supported,
                v.view.violations,
                v.view.occluded
            );
            log!("reliable with the view: {}", v.reliable);
        }
        Err(e) => log!("register_view failed: {:?}", e),
    }
}

/// Prints a registration's pose and confidence.
fn report(r: &Registration) {
    log!("rotation (w, x, y, z): {:?}", r.pose.rotation);
    log!("translation: {:?}", r.pose.translation);
    log!(
        "residual: {:?}, plane residual {:?} ({:?} of the template's size), fitness {:?}, hypothesis {}, ICP iterations {}, saturated {}",
        r.residual,
        r.plane_residual,
        r.relative_plane_residual,
        r.fitness,
        r.hypothesis,
        r.icp_iterations,
        r.saturated
    );
    log!("reliable: {}", r.reliable);
    if r.ambiguity.is_ambiguous() {
        log!("ambiguous (a symmetric object): {:?}", r.ambiguity);
    }
}
