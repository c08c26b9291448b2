"""Host utilities: atomic files, memory estimates, deprecated-path forwarding."""
