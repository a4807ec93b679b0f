"""Planning: the planner, its plans, NumPy inference, baselines, time parameterisation."""
