"""The thesis's hyperparameters in rl-baselines3-zoo's format, one YAML file per algorithm (``<algo>.yml``).

This folder is installed as the package ``sb3_er.zoo_configs`` (see ``pyproject.toml``), so an installed wheel carries
the files as package data; :func:`sb3_er.zoo.config_path` reads them through ``importlib.resources``.
"""
