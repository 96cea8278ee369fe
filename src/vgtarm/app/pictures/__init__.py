"""The pictures: plots of runs, drawings and animations of the mechanism, and their geometry."""
