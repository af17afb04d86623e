"""Shared inputs of the motion and physics fast-path tests: small configurations and parameter
dicts (tests/ref/motion/cases.py) with the agreement checks of tests/agreement.py.
"""

# The NumPy-side helpers (configs, parameter dicts, masks) are shared with the reference's
# tests; the torch-side checks are the one harness of tests/agreement.py.
from tests.agreement import (DEVICE_SETTINGS, RTOL32, RTOL64, as_tuple, assert_close,  # noqa: F401
                             check_agreement, check_float32, gradcheck_fn, leaves, rebuild, to_numpy, to_torch)
from tests.ref.motion.cases import (RIGID_MASK, TRANSLATION_MASK, column_mask,  # noqa: F401
                                    constant_coefficient_params, map_leaves, mlp_velocity_params, random_params,
                                    small_cfg)
