"""Log readers: each yields time-ordered Ticks with constant memory; chosen by a small registry."""
