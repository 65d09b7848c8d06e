"""Controllers for the vertiport: anything that maps an observation with an action mask to
a legal action."""
