//! QEMU harness (work in progress, see issue 4).
