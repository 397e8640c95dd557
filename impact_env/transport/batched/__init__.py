"""Batched (torch) backend of the impact-transport world; see impact_env.transport.batched.world."""
