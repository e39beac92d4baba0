// The viewer's shaders: instanced spheres and (tapered) cylinders (lit with a head light plus a
// sky light), and coloured world-space lines. Positions are world metres, Y up.

struct Globals {
    view_proj: mat4x4<f32>,
    // xyz: eye position in the world (metres).
    eye: vec4<f32>,
    // x: 1 when the render target is sRGB (colours are then linearised before output).
    params: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;

struct SolidIn {
    // Mesh vertex (unit sphere, or unit cylinder along +Y from 0 to 1).
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    // Instance: sphere centre / cylinder start, radius (at the start), cylinder end, colour,
    // the cylinder's radius at its end (tapered capsules of the body).
    @location(2) a: vec3<f32>,
    @location(3) radius: f32,
    @location(4) b: vec3<f32>,
    @location(5) colour: vec4<f32>,
    @location(6) radius_b: f32,
};

struct SolidOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) colour: vec4<f32>,
};

@vertex
fn vs_sphere(v: SolidIn) -> SolidOut {
    var out: SolidOut;
    out.world = v.a + v.position * v.radius;
    out.normal = v.normal;
    out.clip = globals.view_proj * vec4<f32>(out.world, 1.0);
    out.colour = v.colour;
    return out;
}

@vertex
fn vs_cylinder(v: SolidIn) -> SolidOut {
    // An orthonormal frame whose Y axis runs from a to b; the radial scale is uniform, so
    // normals transform with the rotation alone.
    let axis = v.b - v.a;
    let len = length(axis);
    var y = vec3<f32>(0.0, 1.0, 0.0);
    if (len > 1e-6) {
        y = axis / len;
    }
    var helper = vec3<f32>(1.0, 0.0, 0.0);
    if (abs(y.x) > 0.9) {
        helper = vec3<f32>(0.0, 0.0, 1.0);
    }
    let x = normalize(cross(helper, y));
    let z = cross(x, y);
    // The radius runs from `radius` at a to `radius_b` at b; a side's normal tilts towards the
    // narrower end by the taper (caps keep their axial normals).
    let r = mix(v.radius, v.radius_b, v.position.y);
    var n = v.normal;
    if (abs(n.y) < 0.5) {
        n = normalize(vec3<f32>(n.x * len, v.radius - v.radius_b, n.z * len));
    }
    var out: SolidOut;
    out.world = v.a + x * (v.position.x * r) + y * (v.position.y * len) + z * (v.position.z * r);
    out.normal = x * n.x + y * n.y + z * n.z;
    out.clip = globals.view_proj * vec4<f32>(out.world, 1.0);
    out.colour = v.colour;
    return out;
}

fn to_target(c: vec3<f32>) -> vec3<f32> {
    if (globals.params.x > 0.5) {
        return pow(c, vec3<f32>(2.2));
    }
    return c;
}

@fragment
fn fs_solid(f: SolidOut) -> @location(0) vec4<f32> {
    let n = normalize(f.normal);
    let to_eye = normalize(globals.eye.xyz - f.world);
    let head = max(dot(n, to_eye), 0.0);
    let sky = 0.5 + 0.5 * n.y;
    let shade = 0.28 + 0.55 * head + 0.22 * sky;
    let spec = pow(head, 24.0) * 0.18;
    let rgb = min(f.colour.rgb * shade + vec3<f32>(spec), vec3<f32>(1.0));
    return vec4<f32>(to_target(rgb), f.colour.a);
}

struct LineIn {
    @location(0) position: vec3<f32>,
    @location(1) colour: vec4<f32>,
};

struct LineOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) colour: vec4<f32>,
};

@vertex
fn vs_line(v: LineIn) -> LineOut {
    var out: LineOut;
    out.clip = globals.view_proj * vec4<f32>(v.position, 1.0);
    out.colour = v.colour;
    return out;
}

@fragment
fn fs_line(f: LineOut) -> @location(0) vec4<f32> {
    return vec4<f32>(to_target(f.colour.rgb), f.colour.a);
}
