"""Host utilities: atomic files, memory estimates."""
