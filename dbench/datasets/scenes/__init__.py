"""What a scene is and the procedural catalogue: the Scene record, the catalogue's scenes, their building blocks, their declared parameters and the call of a scene's build."""
