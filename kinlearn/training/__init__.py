"""Training: the generic loop, the FM/IM, and the trajectory models through frozen models."""
