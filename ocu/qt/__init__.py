"""Qt adapters: the one place where the pure packages meet Qt (signals, timers, threads)."""
