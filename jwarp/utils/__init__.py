"""Host utilities: atomic files, memory estimates, the argument checker."""
