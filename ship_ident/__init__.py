"""ship_ident: online identification of USV steering dynamics (Nomoto models).

The numeric core (dataset, structure, effects, estimators, simulator,
diagnosis) has no ROS in it; ``node`` and ``cli`` are thin doors onto it.
"""

__version__ = "0.1.0"
