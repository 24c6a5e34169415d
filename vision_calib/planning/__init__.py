"""planning: the joint values to command for a calibration (``vision-calib plan``): candidate poses within the
joint limits, kept when collision-free with a clearance (FCL, :mod:`.collision`) and the target measurable
(:mod:`.view`), D-optimal selection for the base parameters, a short drivable tour, and the accuracy they
predict (:mod:`.plan`)."""
