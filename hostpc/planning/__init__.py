"""Pose planning, pure numerics (no I/O): D-optimal selection and the identifiability
check of a plan (`design`), travel order (`tour`), sphere contact planning and geometry
(`sphere_setup`, `sphere_contacts`, `sphere_geometry`), the humanoid's look-at poses
(`dual_loop_poses`). It takes a model and candidates and returns poses."""
