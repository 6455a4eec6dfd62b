"""Built-in scenarios; importing this package registers them."""
