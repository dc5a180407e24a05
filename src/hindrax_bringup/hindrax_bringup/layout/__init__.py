"""Launch layouts: composed processes, launch files read and run, the emulated devices, the health verdict."""
