//! Device side of the QEMU harness.
//!
//! QEMU's generic loader puts a test-vector container at the start of the
//! board's data region (the MPS2 PSRAM, 16 MiB, big enough for the
//! paper-size model; 128 KiB of the micro:bit's flash; see
//! `pcrnet_firmware_example::board`).
//! For every model in it, this program parses the model in place, then for
//! every case of that model measures the encoder alone and the whole
//! inference with the SysTick instruction counter, runs the iterative
//! network pass and every `register` call the case asks for (instructions
//! and peak stack measured per call), and prints the outputs as text over
//! semihosting. The host compares them with its own, bit for bit.
//!
//! Container, version 5 (all u32 little-endian, offsets from its start,
//! 4-aligned):
//! - header: `b"PCRV" version n_models n_cases`;
//! - `n_models x (blob_offset, blob_len)`;
//! - `n_cases x (model, cloud_offset, n_points, tile, iterations,
//!   n_registrations, options_offset)`: the cloud is `n_points x [f32; 3]`
//!   at `cloud_offset`; `iterations` i-PCRNet passes (tolerance 0) run
//!   after the inference when non-zero;
//! - at `options_offset`, `n_registrations` option sets of 12 words each,
//!   every `Options` field: `passes tolerance hypotheses screen_iterations
//!   icp_iterations metric icp_tolerance icp_distance inlier_distance
//!   max_points max_residual lk_iterations` (counts as u32, f32 as their bits, metric 0
//!   point-to-point / 1 point-to-plane).
//!
//! Output lines (f32 as 8 hex digits of their bits, `{:?}` for errors):
//! - `model M load_stack STACK` (peak stack of parsing the blob), then
//!   `model M load ok int8`, `model M load ok f32` (parsed, no cases run) or
//!   `model M load error E`;
//! - `case C ok ENCODE_INSTR INFER_INSTR STACK feature HEX head H0..H6 pose Q0..T2`
//!   (or `pose_error E`), or `case C error ENCODED E`;
//! - `case C iter ok PASSES Q0..T2`, or `case C iter error E`;
//! - `case C reg K ok INSTR STACK QW QX QY QZ TX TY TZ RESIDUAL RELATIVE
//!   FITNESS RMSE PLANE RELATIVE_PLANE HYPOTHESIS PASSES LK_ITERATIONS
//!   ICP_ITERATIONS SATURATED OUT_OF_RANGE none|Point|Line true|false AXIS
//!   TURN` (the ambiguity as `pcrnet_core::testing::describe_ambiguity`
//!   words it), or `case C reg K error INSTR STACK E`;
//! - after each successful `register`, `case C track K START ok INSTR STACK`
//!   and the same fields, then `Kept|Recovered|Lost`, or `case C track K
//!   START error INSTR STACK E`: a tracking step with the same options from
//!   START, `held` (the registered pose) and, with `Options::default()`,
//!   `predicted` (`pose::predict(IDENTITY, pose)`; the host's
//!   `vectors::track_starts` is the same rule).
//! - after each successful `register` with `Options::default()`, `case C
//!   feature K ok INSTR BITS` (the feature-space check), or `... error
//!   INSTR E`; and `case C view K ok INSTR STACK` with a registration's
//!   fields then `SUPPORTED VIOLATIONS OCCLUDED UNOBSERVED PASSED
//!   RELIABLE` (`register_view` from `testing::harness_viewpoint`), or
//!   `case C view K error INSTR STACK E`.
#![no_std]
#![no_main]

use core::fmt::Write;

use heapless::String;
#[cfg(target_arch = "arm")]
use panic_semihosting as _;
use pcrnet_core::pose::{self, Pose};
use pcrnet_core::{Error, F32Model, Int8Model, Metric, Options, Registration};
use pcrnet_firmware_example::board::{exit, print};
use pcrnet_firmware_example::{icount, stack};

use pcrnet_firmware_example::board::{DATA_BASE as BASE, DATA_LEN};
/// Scratch for every model of the case set (the micro:bit's 16 KiB of RAM
/// takes its small models only).
#[cfg(not(feature = "microbit"))]
const SCRATCH: usize = 64 * 1024;
#[cfg(feature = "microbit")]
const SCRATCH: usize = 4 * 1024;
/// Longest output line (a paper-size feature is 2,048 hex digits).
#[cfg(not(feature = "microbit"))]
const LINE: usize = 8192;
#[cfg(feature = "microbit")]
const LINE: usize = 1024;
/// Container version this runner reads.
const VERSION: u32 = 5;
/// u32 words per case in the container's table.
const CASE_WORDS: usize = 7;
/// u32 words per option set.
const OPTIONS_WORDS: usize = 13;

fn word(index: usize) -> u32 {
    // SAFETY: the data region is always mapped; reads stay inside it.
    unsafe { core::ptr::read_volatile((BASE + 4 * index.min(DATA_LEN / 4 - 1)) as *const u32) }
}

fn bytes(offset: u32, len: u32) -> &'static [u8] {
    let (o, l) = (offset as usize, len as usize);
    let l = l.min(DATA_LEN.saturating_sub(o));
    // SAFETY: inside the data region, which nothing else writes while we run.
    unsafe { core::slice::from_raw_parts((BASE + o.min(DATA_LEN)) as *const u8, l) }
}

fn points(offset: u32, n: u32) -> &'static [[f32; 3]] {
    let (o, n) = (offset as usize, n as usize);
    let n = n.min(DATA_LEN.saturating_sub(o) / 12);
    // SAFETY: the host aligns clouds to 4 bytes inside the data region; [f32; 3] has
    // alignment 4 and every bit pattern is a valid f32.
    unsafe { core::slice::from_raw_parts((BASE + o.min(DATA_LEN)) as *const [f32; 3], n) }
}

/// The option set at word `index` (see the container layout above; the
/// host's `vectors::options_from_words` mirrors this).
fn read_options(index: usize) -> Options {
    let w = |k: usize| word(index + k);
    Options {
        passes: w(0) as usize,
        tolerance: f32::from_bits(w(1)),
        hypotheses: w(2) as usize,
        screen_iterations: w(3) as usize,
        icp_iterations: w(4) as usize,
        metric: if w(5) == 0 {
            Metric::PointToPoint
        } else {
            Metric::PointToPlane
        },
        icp_tolerance: f32::from_bits(w(6)),
        icp_distance: f32::from_bits(w(7)),
        inlier_distance: f32::from_bits(w(8)),
        max_points: w(9) as usize,
        max_residual: f32::from_bits(w(10)),
        lk_iterations: w(11) as usize,
        network_points: w(12) as usize,
    }
}

/// Prints one line (semihosting is slow per call: build the line first).
fn emit(line: &str) {
    print(line);
}

/// Prints a formatted line.
macro_rules! say {
    ($($t:tt)*) => {{
        let mut l: String<256> = String::new();
        let _ = write!(l, $($t)*);
        emit(&l);
    }};
}

/// Appends a registration's fields: the pose, the six distances (hex bits),
/// `hypothesis passes lk_iterations icp_iterations saturated
/// out_of_range`, the degeneracy, the verdict and the ambiguity (two words).
fn write_registration(line: &mut String<LINE>, r: &Registration) {
    for v in r.pose.rotation.iter().chain(&r.pose.translation) {
        let _ = write!(line, " {:08x}", v.to_bits());
    }
    for v in [
        r.residual,
        r.relative_residual,
        r.fitness,
        r.inlier_rmse,
        r.plane_residual,
        r.relative_plane_residual,
    ] {
        let _ = write!(line, " {:08x}", v.to_bits());
    }
    let _ = write!(
        line,
        " {} {} {} {} {} {} ",
        r.hypothesis, r.passes, r.lk_iterations, r.icp_iterations, r.saturated, r.out_of_range
    );
    let _ = match r.degenerate {
        None => write!(line, "none"),
        Some(d) => write!(line, "{d:?}"),
    };
    let _ = write!(line, " {} ", r.reliable);
    let _ = pcrnet_core::testing::describe_ambiguity(&r.ambiguity, line);
}

/// Working memory of every call; only `main` names it.
static mut SCRATCH_BUF: [i8; SCRATCH] = [0; SCRATCH];

#[cfg_attr(target_arch = "arm", cortex_m_rt::entry)]
#[cfg_attr(target_arch = "riscv32", riscv_rt::entry)]
fn main() -> ! {
    // SAFETY: main runs once and is the only code that names SCRATCH_BUF,
    // so this is the only reference to it.
    let scratch: &'static mut [i8; SCRATCH] = unsafe { &mut *core::ptr::addr_of_mut!(SCRATCH_BUF) };
    let Some(counter) = icount::counter() else {
        say!("error instruction counter unavailable");
        exit(false);
    };

    // Calibration: 2 instructions per iteration, 1,000,000 iterations.
    let t0 = counter.instructions();
    icount::calibration_loop(1_000_000);
    let t1 = counter.instructions();
    say!("calibration {} {}", 2 * 1_000_000u64, t1 - t0);

    if &word(0).to_le_bytes() != b"PCRV" || word(1) != VERSION {
        say!("error no test vectors at {:#x}", BASE);
        exit(false);
    }
    let (n_models, n_cases) = (word(2) as usize, word(3) as usize);
    say!("static_ram {}", stack::static_ram());
    let cases = 4 + 2 * n_models;
    let mut line: String<LINE> = String::new();
    for m in 0..n_models {
        let blob = bytes(word(4 + 2 * m), word(5 + 2 * m));
        // The load verdict, as the host's `hostile::load_verdict` words it,
        // and the stack parsing and validating the blob takes.
        let baseline = stack::paint();
        let loaded = Int8Model::from_bytes(blob);
        let f32_loaded = match loaded {
            Err(Error::WrongKind { .. }) => Some(F32Model::from_bytes(blob).map(|_| ())),
            _ => None,
        };
        say!("model {} load_stack {}", m, stack::used_below(baseline));
        let model = match loaded {
            Ok(model) => {
                say!("model {} load ok int8", m);
                model
            }
            Err(Error::WrongKind { .. }) => {
                match f32_loaded {
                    Some(Ok(())) => say!("model {} load ok f32", m),
                    Some(Err(e)) => say!("model {} load error {:?}", m, e),
                    None => {}
                }
                continue;
            }
            Err(e) => {
                say!("model {} load error {:?}", m, e);
                continue;
            }
        };
        for c in (0..n_cases).filter(|&c| word(cases + CASE_WORDS * c) as usize == m) {
            run_case(c, cases, &model, scratch, &counter, &mut line);
        }
        #[cfg(not(feature = "microbit"))]
        run_scene(m, &model, scratch, &counter, &mut line);
    }
    say!("done");
    exit(true)
}

/// One case of the container (`cases`: its table's first word): the
/// inference, the i-PCRNet passes, the registrations and what follows each.
/// Not inlined: its locals (results, poses, registrations) stay out of
/// `main`'s frame, which on the micro:bit's 16 KiB of RAM must leave room
/// for loading a blob.
#[inline(never)]
fn run_case(
    c: usize,
    cases: usize,
    model: &Int8Model,
    scratch: &mut [i8],
    counter: &icount::Counter,
    line: &mut String<LINE>,
) {
    let entry = |k: usize| word(cases + CASE_WORDS * c + k);
    let (cloud, tile) = (points(entry(1), entry(2)), entry(3) as usize);
    let baseline = stack::paint();
    let e0 = counter.instructions();
    let encoded = model.encode_tiled(cloud, tile, scratch).is_ok();
    let e1 = counter.instructions();
    let result = model.infer_tiled(cloud, tile, scratch).map(|r| {
        let pose = model.pose(&r.head);
        (r, pose)
    });
    let e2 = counter.instructions();
    let peak = stack::used_below(baseline);
    line.clear();
    match result {
        Ok((r, pose)) => {
            let _ = write!(line, "case {c} ok {} {} {peak} feature ", e1 - e0, e2 - e1);
            for &v in r.feature {
                let _ = write!(line, "{:02x}", v as u8);
            }
            let _ = write!(line, " head");
            for v in r.head {
                let _ = write!(line, " {v}");
            }
            match pose {
                Ok(p) => {
                    let _ = write!(line, " pose");
                    for v in p.rotation.iter().chain(&p.translation) {
                        let _ = write!(line, " {:08x}", v.to_bits());
                    }
                }
                Err(e) => {
                    let _ = write!(line, " pose_error {e:?}");
                }
            }
        }
        Err(e) => {
            let _ = write!(line, "case {c} error {encoded} {e:?}");
        }
    }
    emit(line);
    let iterations = entry(4) as usize;
    if iterations > 0 {
        line.clear();
        match model.network_pose(cloud, iterations, 0.0, scratch) {
            Ok((p, n)) => {
                let _ = write!(line, "case {c} iter ok {n}");
                for v in p.rotation.iter().chain(&p.translation) {
                    let _ = write!(line, " {:08x}", v.to_bits());
                }
            }
            Err(e) => {
                let _ = write!(line, "case {c} iter error {e:?}");
            }
        }
        emit(line);
    }
    let (n_registrations, options_at) = (entry(5) as usize, entry(6) as usize / 4);
    for k in 0..n_registrations {
        let options = read_options(options_at + OPTIONS_WORDS * k);
        let baseline = stack::paint();
        let r0 = counter.instructions();
        let result = model.register(cloud, &options, scratch);
        let r1 = counter.instructions();
        let peak = stack::used_below(baseline);
        line.clear();
        match &result {
            Ok(r) => {
                let _ = write!(line, "case {c} reg {k} ok {} {peak}", r1 - r0);
                write_registration(line, r);
            }
            Err(e) => {
                let _ = write!(line, "case {c} reg {k} error {} {peak} {e:?}", r1 - r0);
            }
        }
        emit(line);
        let Ok(r) = result else {
            continue;
        };
        // The feature-space check of the pose (the rule of the
        // host's `feature::checked`: default options only).
        if options == Options::default() {
            let f0 = counter.instructions();
            let checked = model.feature_distance(cloud, &r.pose, scratch);
            let f1 = counter.instructions();
            line.clear();
            let _ = match checked {
                Ok(d) => write!(
                    line,
                    "case {c} feature {k} ok {} {:08x}",
                    f1 - f0,
                    d.to_bits()
                ),
                Err(e) => write!(line, "case {c} feature {k} error {} {e:?}", f1 - f0),
            };
            emit(line);
            // The registration seen from the harness's viewpoint (the
            // rule of the host's `view::expected`; not on the micro:bit,
            // whose flash it does not fit).
            #[cfg(not(feature = "microbit"))]
            register_view(c, k, cloud, model, scratch, counter, line);
        }
        // Tracking from the registered pose (held), and with the
        // default options also from its constant-velocity
        // prediction after the identity (mostly a fallback).
        let predicted = pose::predict(&Pose::IDENTITY, &r.pose);
        let starts = [("held", r.pose), ("predicted", predicted)];
        let n_starts = if options == Options::default() { 2 } else { 1 };
        for (name, start) in starts.iter().take(n_starts) {
            emit_track((c, k, name), counter, line, || {
                model.track(cloud, start, &options, scratch)
            });
        }
        // The same cloud tracked as a view from the harness's viewpoint,
        // from the starts of the host's `tracking::viewed_starts`.
        #[cfg(not(feature = "microbit"))]
        if options == Options::default() {
            let viewpoint = pcrnet_core::testing::harness_viewpoint(cloud);
            for (name, start) in [("viewed-held", r.pose), ("viewed", predicted)] {
                emit_track((c, k, name), counter, line, || {
                    model.track_view(cloud, &start, viewpoint, &options, scratch, view_buffer())
                });
            }
        }
    }
}

/// `case C track K NAME ...`: the tracking step `step` runs (case `C`,
/// option set `K`, start `NAME`), its instructions and peak stack.
fn emit_track(
    (c, k, name): (usize, usize, &str),
    counter: &icount::Counter,
    line: &mut String<LINE>,
    step: impl FnOnce() -> pcrnet_core::Result<pcrnet_core::Tracking>,
) {
    let baseline = stack::paint();
    let t0 = counter.instructions();
    let tracked = step();
    let t1 = counter.instructions();
    let peak = stack::used_below(baseline);
    line.clear();
    let _ = write!(line, "case {c} track {k} {name} ");
    match tracked {
        Ok(t) => {
            let _ = write!(line, "ok {} {peak}", t1 - t0);
            write_registration(line, &t.registration);
            let _ = write!(line, " {:?}", t.outcome);
        }
        Err(e) => {
            let _ = write!(line, "error {} {peak} {e:?}", t1 - t0);
        }
    }
    emit(line);
}

/// `case C view K ...`: the viewed registration of the cloud (see the
/// module docs), its instructions and peak stack.
#[cfg(not(feature = "microbit"))]
fn register_view(
    c: usize,
    k: usize,
    cloud: &[[f32; 3]],
    model: &Int8Model,
    scratch: &mut [i8],
    counter: &icount::Counter,
    line: &mut String<LINE>,
) {
    let viewpoint = pcrnet_core::testing::harness_viewpoint(cloud);
    let view = view_buffer();
    let baseline = stack::paint();
    let v0 = counter.instructions();
    let seen = model.register_view(cloud, viewpoint, &Options::default(), scratch, view);
    let v1 = counter.instructions();
    let peak = stack::used_below(baseline);
    line.clear();
    match seen {
        Ok(v) => {
            let _ = write!(line, "case {c} view {k} ok {} {peak}", v1 - v0);
            write_registration(line, &v.registration);
            let s = v.view;
            let _ = write!(
                line,
                " {} {} {} {} {} {}",
                s.supported,
                s.violations,
                s.occluded,
                s.unobserved,
                u32::from(s.passed),
                u32::from(v.reliable)
            );
        }
        Err(e) => {
            let _ = write!(line, "case {c} view {k} error {} {peak} {e:?}", v1 - v0);
        }
    }
    emit(line);
}

/// Pixels a side of the viewed registration's image (as the host's `view::side_for`).
#[cfg(not(feature = "microbit"))]
const VIEW_SIDE: usize = pcrnet_core::testing::HARNESS_VIEW_SIDE;

/// The viewed registration's image buffer.
#[cfg(not(feature = "microbit"))]
fn view_buffer() -> &'static mut [f32] {
    static mut VIEW: [f32; VIEW_SIDE * VIEW_SIDE] = [0.0; VIEW_SIDE * VIEW_SIDE];
    // SAFETY: the runner is single-threaded and each borrow ends before
    // the next call (one check at a time).
    unsafe { &mut *core::ptr::addr_of_mut!(VIEW) }
}

/// The scene path on the harness frame ([`pcrnet_core::testing::scene`]):
/// `model M scene segment INSTR` (the scene stages alone), then `model M
/// scene RUN INSTR STACK WORDS...` for RUN `locate` (the network's
/// hypotheses), `sweep` (the template's up axis given) and `follow` (the
/// next frame followed from the sweep's pose and plane: the same frame,
/// the object where it was), each the whole path described word by word,
/// or `model M scene RUN error E`; a frame that cannot be made is `model M
/// scene error E`.
#[cfg(not(feature = "microbit"))]
fn run_scene(
    m: usize,
    model: &Int8Model,
    scratch: &mut [i8],
    counter: &icount::Counter,
    line: &mut String<LINE>,
) {
    use pcrnet_core::scene::{self, SceneOptions};
    use pcrnet_core::testing::scene as harness;
    const W: usize = harness::HARNESS_WIDTH;
    const H: usize = harness::HARNESS_HEIGHT;
    const STEP: usize = 4;
    static mut DEPTH: [u16; W * H] = [0; W * H];
    static mut TEMPLATE: [[f32; 3]; 1024] = [[0.0; 3]; 1024];
    static mut LABELS: [u16; scene::labels_len(W, H, STEP)] = [0; scene::labels_len(W, H, STEP)];
    static mut POINTS: [[f32; 3]; 512] = [[0.0; 3]; 512];
    // SAFETY: run_scene runs on one thread, one call at a time, and is
    // the only code naming these buffers.
    let (depth, template, labels, points) = unsafe {
        (
            &mut *core::ptr::addr_of_mut!(DEPTH),
            &mut *core::ptr::addr_of_mut!(TEMPLATE),
            &mut *core::ptr::addr_of_mut!(LABELS),
            &mut *core::ptr::addr_of_mut!(POINTS),
        )
    };
    if let Err(e) = harness::harness_frame(model, template, depth).map(|_| ()) {
        say!("model {m} scene error {e:?}");
        return;
    }
    let image = match harness::harness_image(depth) {
        Ok(image) => image,
        Err(e) => {
            say!("model {m} scene error {e:?}");
            return;
        }
    };
    let scene_options = SceneOptions::for_object(model.object_radius());
    let s0 = counter.instructions();
    let segmented = scene::segment(&image, &scene_options, labels);
    let s1 = counter.instructions();
    if let Err(e) = segmented {
        say!("model {m} scene error {e:?}");
        return;
    }
    say!("model {m} scene segment {}", s1 - s0);
    let options = Options::default();
    let swept = SceneOptions {
        up: Some(harness::HARNESS_UP),
        ..scene_options
    };
    // Where the sweep left the object: the follow run's start.
    let mut last = (pcrnet_core::Pose::IDENTITY, None);
    for name in ["locate", "sweep", "follow"] {
        let baseline = stack::paint();
        let l0 = counter.instructions();
        let located = match name {
            "follow" => model.follow(
                &image,
                &scene_options,
                &last.0,
                last.1,
                &options,
                labels,
                points,
                scratch,
            ),
            _ => model.locate(
                &image,
                if name == "sweep" {
                    &swept
                } else {
                    &scene_options
                },
                harness::HARNESS_CANDIDATES,
                &options,
                labels,
                points,
                scratch,
            ),
        };
        let l1 = counter.instructions();
        let peak = stack::used_below(baseline);
        line.clear();
        match located {
            Ok(located) => {
                if name == "sweep" {
                    last = harness::follow_start(&located);
                }
                let _ = write!(line, "model {m} scene {name} {} {peak} ", l1 - l0);
                let _ = harness::describe(&located, line);
            }
            Err(e) => {
                let _ = write!(line, "model {m} scene {name} error {e:?}");
            }
        }
        emit(line);
    }
}
