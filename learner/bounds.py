"""The network's shape and Lipschitz bounds (learner.network applies them), without torch.

The rotor speeds are the control input, and the controller finds the input that the
prediction itself depends on (a fixed point). Neural Lander's stability condition is that the
prediction's Lipschitz constant in the control input is below 1 (newtons of predicted force
per newton of thrust). The first layer's rotor-speed columns get their own bound for it.
"""

from __future__ import annotations

import numpy as np

LAYERS = (12, 25, 30, 15, 3)  # thesis 3.5.3: 12 features -> 3 force components, ReLU

# Neural Lander keeps each layer at 2. Here z is standardised over flights up to 1.5 m, so the
# last 3 cm above the ground are a tenth of a standard deviation across which the effect
# grows tenfold: at 2 per layer (16 overall) the network cannot be that steep in z and
# explains the effect through the rotor speeds instead. 4 per layer lets it follow z; the
# control input keeps its own, much tighter bound (below).
DEFAULT_LAYER_BOUND = 4.0
CONTROL_COLUMNS = (8, 9, 10, 11)  # n0..n3 among the 12 features (learner.dataset.FEATURES)
DEFAULT_CONTROL_GAIN_BOUND = 0.5  # N of predicted force per N of thrust, at most


def control_column_bound(
    control_gain_bound: float,
    x_std_rotor_rad_s: np.ndarray,
    y_std_n: float,
    thrust_coefficient_n_s2: float,
    hover_rotor_speed_rad_s: float,
    layer_bound: float,
    layers: int = 4,
) -> float:
    """The spectral norm bound of the first layer's rotor-speed columns (standardised units)
    that keeps |d f / d thrust| <= control_gain_bound near hover.

    The rotor-speed path's Lipschitz constant in physical units is at most
    b * layer_bound^(layers - 1) * y_std / min(x_std_n) [N per rad/s, 2-norm over the four
    speeds]; a thrust change dT with all four speeds moving together has ||dn|| = dT /
    (4 C_T n_hover).
    """
    newton_per_rad_s = control_gain_bound * 4.0 * thrust_coefficient_n_s2 * hover_rotor_speed_rad_s
    standardised = newton_per_rad_s * float(np.min(x_std_rotor_rad_s)) / y_std_n
    return standardised / layer_bound ** (layers - 1)
