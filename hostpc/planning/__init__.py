"""Pose planning, pure numerics (no I/O): D-optimal selection and the identifiability
check of a plan (`design`), travel order (`tour`), approach directions (`approach`), the
verification poses (`verify_poses`), the predicted robot time (`robot_time`); a kind's own
planning lives in its folder (hostpc/kinds/<name>/). It takes a model and candidates and
returns poses."""
