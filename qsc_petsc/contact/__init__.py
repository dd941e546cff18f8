"""Node-to-segment contact: search, projection, constraint rows, penalty, and their parallel assembly."""
