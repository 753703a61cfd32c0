"""Built-in sitframe plugins. Each module is one plugin, registered by entry point."""
