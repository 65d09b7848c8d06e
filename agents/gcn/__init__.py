"""The learned ATC: a shared GCN actor, a centralised critic, a masked categorical distribution
for rsl-rl-lib, vector-env adapters for both training modes, and the training entry point."""
