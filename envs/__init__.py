"""The world: room styles and generator (pure data), ground truth, and the dm_control/MuJoCo
arena, entities, robot, task and rendering."""
