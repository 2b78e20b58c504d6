"""The simulated sensors, one module per measurement kind: `stereo_target` (stereo camera
images; rendered by `render`, rig-calibration views from `board_views`), `sphere_probe`
(touch probe contact), `world_point` (laser tracker), `dual_loop` (the humanoid head's
triangulating stereo camera). Each takes the true pose it needs as an argument."""
