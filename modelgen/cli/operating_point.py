"""``modelgen linearize --equilibrium``: the rest point searched from the
configuration of ``--at`` (over the scene's initial state), with the fixes a
command line can apply."""
from __future__ import annotations

import numpy as np

from modelgen.errors import ModelgenError, SimulationError


def check_equilibrium(model) -> None:
    """Refuse ``--equilibrium`` for a constrained model before anything is built:
    the search does not stay on the constraints (``cm.equilibrium`` refuses it)."""
    if model.constraints:
        raise ModelgenError(f"--equilibrium: {model.name} is constrained, and the rest-point "
                            "search does not stay on its constraints; fix: leave out "
                            "--equilibrium and give a configuration at rest on the "
                            "constraints with --at NAME=VALUE (a point off them is "
                            "refused with the values that close them)")


def at_rest(cm, x0, u, p, t) -> np.ndarray:
    """The state at rest at the equilibrium found from ``x0``'s configuration, printed.
    A failure keeps its own exit status (4 when no rest point is found, as for the
    linearization itself; 2 for a start where the model is not defined), and a
    failed search says that ``--at`` gives the guess."""
    try:
        q = cm.equilibrium(x0[:cm.nq], u=u, p=p, t=t)
    except SimulationError as exc:
        if type(exc) is not SimulationError:      # a subclass says it all, with its status
            raise
        raise SimulationError(f"--equilibrium: {exc} (on the command line the guess is "
                              f"--at NAME=VALUE over the scene's initial state)") from exc
    print("equilibrium " + ", ".join(f"{c}={v:.12g}" for c, v in zip(cm.coordinates, q)))
    return np.concatenate([q, np.zeros(cm.n)])
