//! The QEMU harness: test vectors computed by `pcrnet-core` on the host,
//! run by the same code cross-compiled for a Cortex-M4F under QEMU, and
//! compared bit for bit.
//!
//! 1. [`vectors`] builds models and clouds (seeded), the `register` option
//!    sets of each case and the container QEMU loads into the board's data
//!    region (PSRAM on the MPS2 boards), with the
//!    host's expected outputs;
//! 2. [`qemu`] cross-compiles the device runner (`tests/firmware`) and runs it
//!    with a timeout;
//! 3. [`compare`] parses the device's lines and compares every value with
//!    the host's, naming the first that differs;
//! 4. [`elf`] reads flash and RAM sizes from the firmware images;
//! 5. [`c_example`] does the same for the C firmware example, through the
//!    C API;
//! 6. [`layers`] measures instructions per MAC layer by layer;
//! 7. [`plan`] says what a run covers: the models of each case set, their
//!    clouds and option sets, and the cases built from them;
//! 8. [`tracking`] adds the tracking steps after each registration: their
//!    starts, the host's results, the device's lines and their comparison;
//! 9. [`scene`] adds the scene path: a generated depth frame, the scene
//!    stages and `locate`, per model;
//! 10. [`figures`] prints the instruction counts CI's log carries on their
//!     own lines (the shipped model's registration and tracking step,
//!     PointNetLK's registration and step).

pub mod c_example;
pub mod compare;
pub mod elf;
pub mod feature;
pub mod figures;
pub mod hostile;
pub mod layers;
pub mod plan;
pub mod qemu;
pub mod scene;
pub mod tracking;
pub mod vectors;
pub mod view;
