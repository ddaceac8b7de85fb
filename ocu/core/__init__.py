"""The control core: the controller manager's thread and the GUI's guarded handle on the model."""
