"""The Drake cell: diagram builder, SlotMonitor and Supervisor systems."""
