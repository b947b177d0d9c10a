"""Simulated worlds and logs (sample logs with ground truth, closed-loop scenarios)."""
