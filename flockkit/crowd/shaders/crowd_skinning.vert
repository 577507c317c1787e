#version 330 core
// flockkit crowd skinning: the reference vertex shader of flockkit.crowd.textures.
//
// Draw one skinned mesh (flockkit.crowd.read_skin) instanced, one instance per agent part, with
// the animation textures of flockkit.crowd.bake_textures and one flockkit.crowd.TEXTURE_INSTANCE
// record per instance (flockkit.crowd.instance_buffer). flockkit.crowd.skin is its numpy
// reference: the same fetches and the same arithmetic, in float64.
//
// u_animation: RGBA32F, 5 J texels wide, one row per baked frame; per joint: skinning matrix rows
//   0, 1, 2 (joint world @ inverse bind), local rotation (x, y, z, w), local translation (x, y, z, 0).
// u_skeleton: RGBA32F, 4 J texels wide, one row; per joint: inverse bind rows 0, 1, 2 and
//   (scale x, y, z, parent index; -1 for a root).
// Vertex joints are integers: bind them with glVertexAttribIPointer, as the instance's rows.

uniform sampler2D u_animation;
uniform sampler2D u_skeleton;
uniform mat4 u_view_projection;

layout(location = 0) in vec3 a_position;   // bind space
layout(location = 1) in vec3 a_normal;
layout(location = 2) in ivec4 a_joints;    // skeleton joint indices
layout(location = 3) in vec4 a_weights;    // summing to 1
// per instance (divisor 1): TEXTURE_INSTANCE's rows, fractions and weight, and the agent's root
layout(location = 4) in ivec4 a_rows;      // source rows a, b; target rows a, b (-1: none)
layout(location = 5) in vec3 a_blend;      // source fraction, target fraction, weight
layout(location = 6) in mat4 a_root;       // model to world (locations 6 to 9)

out vec3 v_normal;

// the deepest joint chain followed (a skeleton deeper than this is cut short)
const int MAX_DEPTH = 64;

vec4 animation(int row, int joint, int texel) {
    return texelFetch(u_animation, ivec2(5 * joint + texel, row), 0);
}

vec4 skeleton(int joint, int texel) {
    return texelFetch(u_skeleton, ivec2(4 * joint + texel, 0), 0);
}

// a matrix from its rows 0, 1, 2 (the last row 0, 0, 0, 1); GLSL builds matrices from columns
mat4 from_rows(vec4 r0, vec4 r1, vec4 r2) {
    return transpose(mat4(r0, r1, r2, vec4(0.0, 0.0, 0.0, 1.0)));
}

// spherical interpolation of unit quaternions the shorter way round (rigid.slerp)
vec4 slerp(vec4 a, vec4 b, float u) {
    float d = dot(a, b);
    if (d < 0.0) { b = -b; d = -d; }
    float angle = acos(min(d, 1.0));
    float s = sin(angle);
    if (s < 1e-6) return normalize(mix(a, b, u));
    return (sin((1.0 - u) * angle) * a + sin(u * angle) * b) / s;
}

// normalized linear interpolation, the shorter way round (rigid.nlerp): the crowd's blend
vec4 nlerp(vec4 a, vec4 b, float u) {
    if (dot(a, b) < 0.0) b = -b;
    return normalize(mix(a, b, u));
}

// a joint's local rotation and translation `fraction` of the way from row a to row b
void between(int a, int b, float fraction, int joint, out vec4 q, out vec3 t) {
    q = animation(a, joint, 3);
    t = animation(a, joint, 4).xyz;
    if (fraction > 0.0) {
        q = slerp(q, animation(b, joint, 3), fraction);
        t = mix(t, animation(b, joint, 4).xyz, fraction);
    }
}

// a joint's local transform T R S, the source and (while blending) the target mixed
mat4 local_matrix(int joint) {
    vec4 q; vec3 t;
    between(a_rows.x, a_rows.y, a_blend.x, joint, q, t);
    if (a_rows.z >= 0) {
        vec4 tq; vec3 tt;
        between(a_rows.z, a_rows.w, a_blend.y, joint, tq, tt);
        if (a_blend.z >= 1.0) { q = tq; t = tt; }
        else if (a_blend.z > 0.0) { q = nlerp(q, tq, a_blend.z); t = mix(t, tt, a_blend.z); }
    }
    vec3 scale = skeleton(joint, 3).xyz;
    float x = q.x, y = q.y, z = q.z, w = q.w;
    mat3 r = mat3(  // columns
        1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + z * w), 2.0 * (x * z - y * w),
        2.0 * (x * y - z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + x * w),
        2.0 * (x * z + y * w), 2.0 * (y * z - x * w), 1.0 - 2.0 * (x * x + y * y));
    return mat4(vec4(r[0] * scale.x, 0.0), vec4(r[1] * scale.y, 0.0), vec4(r[2] * scale.z, 0.0), vec4(t, 1.0));
}

// the skinning matrix of `joint`: baked for a whole frame without a blend, else by forward
// kinematics of the mixed local transforms up the joint's chain, times its inverse bind matrix
mat4 skinning(int joint, bool steady) {
    if (steady) {
        return from_rows(animation(a_rows.x, joint, 0), animation(a_rows.x, joint, 1), animation(a_rows.x, joint, 2));
    }
    mat4 world = local_matrix(joint);
    int parent = int(skeleton(joint, 3).w);
    for (int depth = 0; depth < MAX_DEPTH && parent >= 0; ++depth) {
        world = local_matrix(parent) * world;
        parent = int(skeleton(parent, 3).w);
    }
    return world * from_rows(skeleton(joint, 0), skeleton(joint, 1), skeleton(joint, 2));
}

void main() {
    if (a_rows.x < 0) {  // no part to draw: outside the clip volume
        gl_Position = vec4(0.0, 0.0, 2.0, 1.0);
        v_normal = vec3(0.0);
        return;
    }
    bool steady = a_blend.z == 0.0 && a_blend.x == 0.0;
    mat4 m = mat4(0.0);
    for (int k = 0; k < 4; ++k) {
        if (a_weights[k] > 0.0) m += a_weights[k] * skinning(a_joints[k], steady);
    }
    gl_Position = u_view_projection * (a_root * (m * vec4(a_position, 1.0)));
    v_normal = normalize(mat3(a_root) * (mat3(m) * a_normal));
}
