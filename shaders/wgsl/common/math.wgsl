// Small math helpers shared by several passes.

// Rotation matrix of quaternion q = (w, x, y, z), normalised here; columns are the rotated axes.
fn quat_to_mat3(q_in: vec4<f32>) -> mat3x3<f32> {
    let q = q_in * inverseSqrt(dot(q_in, q_in));
    let w = q.x;
    let x = q.y;
    let y = q.z;
    let z = q.w;
    return mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        vec3<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        vec3<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
}

// Component `i` (0-3) of v by selects: an indexed private vector would go to scratch memory on CPU drivers.
fn component4(v: vec4<f32>, i: u32) -> f32 {
    return select(select(select(v.x, v.y, i == 1u), v.z, i == 2u), v.w, i == 3u);
}

fn ceil_div(a: u32, b: u32) -> u32 {
    return (a + b - 1u) / b;
}

// u32(x) for a whole number x in [0, 2^23) (a pixel coordinate), from the float's bits: adding 2^23
// puts x in the mantissa exactly. Lavapipe runs u32() of a float, which must saturate, as a scalar
// loop over the lanes; this way is a vector add and a bit cast (images bit-identical).
fn whole_u32(x: f32) -> u32 {
    return bitcast<u32>(x + 8388608.0) - 0x4B000000u;
}
