"""The scene: shapes stored once, objects placed by poses or given world vertices, their motion, which
pairs may collide (worlds, groups, excluded pairs), and the flat device arrays every stage reads."""
