"""The hybrid controller on a real arm: the controller's side of the diagram fed from Drake's LCM
drivers (``controller_side``), a simulated robot behind the same messages (``robot_side``), the
safety a real arm needs (``watchdog``, ``command``) and the loops that run them (``loop``)."""
