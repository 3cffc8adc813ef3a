# Headless Blender Mantaflow smoke (or fire) simulation writing OpenVDB caches: the real
# simulated volumes of lpmbake's benchmarks and tests (run through make_blender_smoke.sh).
#   blender -b --factory-startup --python blender_smoke.py -- --out DIR [--res 128]
#           [--end 30] [--fire] [--vorticity 0.2]
# Output: DIR/data/fluid_data_NNNN.vdb for frames 1..end, grids density, temperature,
# flame (fire), velocity, shadow; 32-bit floats; Blender's Z-up world.
# Traps (reference/ecosystem.md): the domain's cache type is set only after the flow
# exists and the view layer is updated; bake_all runs in a context override with the
# domain active.
import argparse
import sys

import bpy


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    ap = argparse.ArgumentParser(prog="blender_smoke.py")
    ap.add_argument("--out", required=True, help="cache directory")
    ap.add_argument("--res", type=int, default=128, help="voxels along the domain's longest side")
    ap.add_argument("--end", type=int, default=30, help="last frame (the first is 1)")
    ap.add_argument("--fire", action="store_true", help="fire and smoke (flame and temperature grids)")
    ap.add_argument("--vorticity", type=float, default=0.2)
    return ap.parse_args(argv)


def add_domain(args):
    # A 2 x 2 x 4 tall box standing on the ground plane: the plume rises along +Z.
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(0.0, 0.0, 2.0))
    domain = bpy.context.active_object
    domain.name = "Domain"
    domain.scale = (1.0, 1.0, 2.0)
    mod = domain.modifiers.new("Fluid", "FLUID")
    mod.fluid_type = "DOMAIN"
    ds = mod.domain_settings
    ds.domain_type = "GAS"
    ds.resolution_max = args.res
    ds.cache_directory = args.out
    ds.cache_data_format = "OPENVDB"
    ds.openvdb_data_depth = "32"
    ds.cache_frame_start = 1
    ds.cache_frame_end = args.end
    ds.vorticity = args.vorticity
    ds.use_noise = False
    ds.use_adaptive_domain = False
    return domain, ds


def add_flow(args):
    # An emitter near the floor, off centre so the plume leans and curls.
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.35, location=(0.15, -0.1, 0.5))
    flow = bpy.context.active_object
    flow.name = "Flow"
    mod = flow.modifiers.new("Fluid", "FLUID")
    mod.fluid_type = "FLOW"
    fs = mod.flow_settings
    fs.flow_type = "BOTH" if args.fire else "SMOKE"
    fs.flow_behavior = "INFLOW"
    fs.flow_source = "MESH"
    fs.surface_distance = 0.5
    fs.density = 1.0
    fs.temperature = 1.5
    if args.fire:
        fs.fuel_amount = 1.0
    fs.use_initial_velocity = True
    fs.velocity_coord = (0.0, 0.0, 1.0)
    return flow


def main():
    args = parse_args()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start = 1
    scene.frame_end = args.end
    domain, ds = add_domain(args)
    add_flow(args)
    bpy.context.view_layer.update()
    ds.cache_type = "ALL"
    for o in scene.objects:
        o.select_set(o == domain)
    bpy.context.view_layer.objects.active = domain
    with bpy.context.temp_override(scene=scene, active_object=domain, object=domain):
        bpy.ops.fluid.bake_all()
    print("blender_smoke: baked frames 1-%d at resolution %d into %s" % (args.end, args.res, args.out))


main()
