"""Recording and replay of rosbag2-compatible MCAP bags without rosbag2 (docs/architecture.md §7, docs/architecture.md
§11.6).

Pure cores (no ROS runtime):
- :mod:`.qos`: QoS profiles in rosbag2's YAML layout, subscription/playback QoS choices;
- :mod:`.metadata`: ``metadata.yaml`` (version 9) as typed objects;
- :mod:`.writer`: :class:`~.writer.BagWriter` (chunks, compression, splitting, fsync per chunk);
  :mod:`.writer_thread`: one writer thread in front of it;
- :mod:`.reader`: raw/decoded messages in log-time order;
- :mod:`.recover`: rebuild truncated files and metadata.yaml; :mod:`.info`: bag summaries;
- :mod:`.playback`: the player's timing; :mod:`.selection`: which topics to record;
- :mod:`.make_test_bags`: the small synthetic bags under ``test/data``.

Thin nodes: :mod:`.recorder_node` (``recorder/start``, ``recorder/stop``), :mod:`.player_node`.
Commands: ``hindrax bag record|play|info|recover``."""
