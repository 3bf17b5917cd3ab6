"""Look-ahead planning: corners, PH fits, feed profile, dynamics check."""
