"""The node graph in one process on the virtual pool: bringup, its executor, the campaign and bag recording runs."""
