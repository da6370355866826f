"""float32 constants for the kernels: a literal 0.0 or 1.0 is a float64 in
numba, and one float64 operand turns a float32 expression into float64 math."""
import numpy as np

F0 = np.float32(0.0)
F1 = np.float32(1.0)
INF = np.float32(np.inf)
