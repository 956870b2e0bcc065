"""Training, evaluation and shipping of learned simulators (the tools behind ``fignet-gym train``,
``evaluate``, ``floor`` and ``ship``)."""
