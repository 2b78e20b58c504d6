"""The dual_loop measurement model (moved to ``hostpc.model.measurements.dual_loop``);
this module keeps the old import path."""

from hostpc.model.measurements.dual_loop import (
    ARMS,
    DUAL_LOOP_FRAMES,
    DualLoop,
    check_dual_loop,
    combined_q,
    dual_loop_context,
    predict_dual_loop,
    tree_of,
)

__all__ = ["ARMS", "DUAL_LOOP_FRAMES", "DualLoop", "check_dual_loop", "combined_q",
           "dual_loop_context", "predict_dual_loop", "tree_of"]
