"""``hindrax bag record|play|info|recover``: rosbag2-compatible MCAP bags without rosbag2 (docs/architecture.md §7).

One module per subcommand; the implementations live in :mod:`hindrax_bringup.recording`."""
