"""The LCD node's display: its screen and menus, and the boot menu its OS shows before the programs
run."""
