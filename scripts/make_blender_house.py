"""Writes two rooms side by side under one flat roof with Blender's own glTF exporter (Blender 3.4
from Debian 12), for bakes no one tuned on: walls, floor and roof are boxes 20 cm thick with
Blender's default double-sided materials. The west room is lit by the sun through a 1.6 x 1.1 m
window in its south wall; the east room is closed and lit by a 60 W point lamp 30 cm under the
ceiling. A table on four legs in each room, a cabinet in the west one, a shelf against the east
wall. No ground: every random surface point lies on the house. Z up, metres.
Run: blender -b --factory-startup --python scripts/make_blender_house.py -- OUT.glb"""
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bpy  # noqa: E402
from blender_scene import start, material, box, light  # noqa: E402

out = start(11)
plaster = material('Plaster', (0.75, 0.72, 0.68))
oak = material('Oak', (0.45, 0.3, 0.18))
walnut = material('Walnut', (0.3, 0.18, 0.1))
# The shell: floor, roof, outer walls and the wall between the rooms.
box('Floor', (-0.2, -0.2, -0.2), (8.4, 4.2, 0.0), oak)
box('Roof', (-0.2, -0.2, 2.6), (8.4, 4.2, 2.8), plaster)
box('WallWest', (-0.2, -0.2, 0.0), (0.0, 4.2, 2.6), plaster)
box('WallEast', (8.2, -0.2, 0.0), (8.4, 4.2, 2.6), plaster)
box('WallMid', (4.0, 0.0, 0.0), (4.2, 4.0, 2.6), plaster)
box('WallNorth', (0.0, 4.0, 0.0), (8.2, 4.2, 2.6), plaster)
# The south wall: four boxes around the west room's window; the east room's part solid.
box('SouthBelow', (0.0, -0.2, 0.0), (4.0, 0.0, 0.9), plaster)
box('SouthAbove', (0.0, -0.2, 2.0), (4.0, 0.0, 2.6), plaster)
box('SouthLeft', (0.0, -0.2, 0.9), (1.2, 0.0, 2.0), plaster)
box('SouthRight', (2.8, -0.2, 0.9), (4.0, 0.0, 2.0), plaster)
box('SouthEast', (4.0, -0.2, 0.0), (8.2, 0.0, 2.6), plaster)
# The west room: a table on four legs and a cabinet.
box('TableA', (1.5, 2.0, 0.72), (2.7, 2.8, 0.76), walnut)
for i, (x, y) in enumerate([(1.55, 2.05), (2.6, 2.05), (1.55, 2.7), (2.6, 2.7)]):
    box('LegA%d' % i, (x, y, 0.0), (x + 0.05, y + 0.05, 0.72), walnut)
box('CabinetA', (3.3, 3.2, 0.0), (3.9, 3.9, 1.8), walnut)
# The east room: a table, a shelf against the east wall, a lamp 30 cm under the ceiling.
box('TableB', (5.5, 1.5, 0.72), (6.9, 2.3, 0.76), walnut)
for i, (x, y) in enumerate([(5.55, 1.55), (6.8, 1.55), (5.55, 2.2), (6.8, 2.2)]):
    box('LegB%d' % i, (x, y, 0.0), (x + 0.05, y + 0.05, 0.72), walnut)
box('ShelfB', (7.7, 0.5, 0.0), (8.15, 3.0, 2.0), oak)
light('POINT', 'Lamp', 60.0, (6.2, 2.0, 2.3), color=(1.0, 0.9, 0.75))
light('SUN', 'Sun', 4.0, (2.0, -3.0, 6.0), rotation=(math.radians(55), 0, math.radians(10)), color=(1.0, 0.95, 0.85))
bpy.ops.export_scene.gltf(filepath=out, export_format='GLB', export_lights=True)
