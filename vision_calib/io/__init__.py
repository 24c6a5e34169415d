"""io stage: data files only, read and written (recorded folders, importers, pose tables, measured-pose files,
camera files, the calibrated-model file); the report is :mod:`vision_calib.report`, the controller exports
:mod:`vision_calib.deploy.export`."""
