"""Plumbing shared by every layer of ``agents``: atomic file writes and the seed ranges."""
