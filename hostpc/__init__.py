"""zerocal host: calibrate robot joint zero offsets.

    import hostpc
    dataset = hostpc.load_dataset("run/dataset.json")
    result = hostpc.fit(dataset, effects=["joint_offsets", "tool", "target"])
    print(result.parameters["joint_offsets.q2"])
"""

from hostpc.dataset import load_dataset, save_dataset
from hostpc.diagnose import Diagnosis, diagnose
from hostpc.fit import FitResult, fit

__all__ = ["load_dataset", "save_dataset", "fit", "FitResult", "diagnose", "Diagnosis"]
__version__ = "0.1.0"
