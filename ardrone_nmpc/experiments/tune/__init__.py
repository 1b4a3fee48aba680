"""``ardrone-nmpc tune``: search space, objective, engines and the Optuna study."""
