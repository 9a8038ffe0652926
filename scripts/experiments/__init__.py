"""The experiments above the robot's behaviour: benchmarks, the demo and the episode runner."""
