"""Built-in plugins: robots and measurement functions."""
