"""Controllers behind one protocol (classical and reinforcement learning) for the ssme-envs plants."""
