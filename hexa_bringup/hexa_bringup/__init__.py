"""hexa_bringup: entry points that start and supervise the hexa graph, the `hexa` CLI, config and DDS profile."""
