"""interpolate stage."""
