"""Built-in machine configurations (YAML), installed as controller.machine_configs."""
