"""The learned and analytic models: FM/IM, the trajectory models, the body model, Algorithm 1's rollout."""
