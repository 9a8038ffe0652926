"""The robot's behaviour: perception, navigation, view planning, acquisition and search."""
