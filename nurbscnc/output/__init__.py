"""Writing results: files (CSV/NPZ) and streams."""
