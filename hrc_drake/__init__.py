"""Task-and-motion stack on Drake for human-robot collaborative assembly."""
