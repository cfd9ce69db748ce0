"""juno: Python harness of the JunoRover FMU (volumetric wheel/soil model, Petersen & McPhee 2013).

Reads measured campaigns, grids LIDAR terrain, drives the FMU through fmpy, identifies the soil
parameters and compares simulation with measurement.
"""

__version__ = "0.1.0"
