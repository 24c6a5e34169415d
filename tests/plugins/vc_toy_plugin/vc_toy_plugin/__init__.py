"""A toy vision_calib plugin (tests/plugins/test_entry_points.py installs it): one robot kind, one target kind."""
