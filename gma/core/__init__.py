"""The lowest layer: what every other layer may use and that uses nothing of GMA's — the error types,
the pinhole camera, atomic file writes and shared argument parsers. No torch or wgpu here, so the
command line can parse its arguments and report errors without loading either."""
