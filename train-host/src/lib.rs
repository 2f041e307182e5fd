//! Host-side training, quantization and export (work in progress, see issue 3).
