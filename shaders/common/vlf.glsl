// Virtual Light Field lookup (seed 002, Eq 4.5): the specular radiance a glossy or mirror
// static surface sends towards the viewer, from the baked tiles. Layout: VlfGpuTables in
// runtime/render/RenderScene.h; every macro comes from the C++ side (ShaderInterface).
//
// A lookup: find the item's face whose plane holds the fragment; take the direction to look
// up (glossy: towards the viewer; mirror: the reflected view direction, where the light
// comes from); locate its spherical triangle by descending the octahedral subdivision; for
// each of the three corner subfields where the face has tiles on that side, project the
// point onto the subfield plane and fetch the 2x2 cells around it (bilinear, over cells that
// hold a value); weight by the barycentrics, renormalised over the corners that answered.

layout(std430, binding = VLF_DIRECTIONS_BINDING) readonly buffer VlfDirections {
    vec4 uVlfDirections[]; // xyz: stored direction (upper hemisphere)
};
layout(std430, binding = VLF_TRIANGLES_BINDING) readonly buffer VlfTriangles {
    ivec4 uVlfTriangles[]; // per leaf triangle, xyz: corner index * 2 + (1 if reversed)
};
layout(std430, binding = VLF_FACES_BINDING) readonly buffer VlfFaces {
    vec4 uVlfFaces[]; // per specular face: (normal, plane offset), (k_s, 1 if mirror)
};
layout(std430, binding = VLF_BLOCKS_BINDING) readonly buffer VlfBlocks {
    ivec4 uVlfBlocks[]; // per (face, direction): (side, s0, t0, sw), (tw, first slot, 0, 0)
};
layout(std430, binding = VLF_SLOTS_BINDING) readonly buffer VlfSlots {
    int uVlfSlots[]; // tile id or -1
};
layout(binding = VLF_ATLAS_UNIT) uniform sampler2D uVlfAtlas; // tiles, VLF_ATLAS_TILES per row

layout(location = UNIFORM_VLF_FACES) uniform ivec2 uVlfFaceRange; // first face, count (0: none)
layout(location = UNIFORM_VLF_PARAMS) uniform ivec4 uVlfParams;   // level, N, m, directions
layout(location = UNIFORM_VLF_FRAME) uniform vec4 uVlfFrame;      // centre xyz, radius
layout(location = UNIFORM_VLF_CELL_SCALE) uniform float uVlfCellScale; // atlas: radiance / this

// The four children of a spherical triangle in descent order (see DirectionSet.cpp).
void vlfChild(inout vec3 a, inout vec3 b, inout vec3 c, vec3 d, out int child) {
    vec3 ab = normalize(a + b), bc = normalize(b + c), ca = normalize(c + a);
    if (dot(d, cross(ca, ab)) < 0.0) { child = 0; b = ab; c = ca; }
    else if (dot(d, cross(ab, bc)) < 0.0) { child = 1; a = ab; c = bc; }
    else if (dot(d, cross(bc, ca)) < 0.0) { child = 2; a = ca; b = bc; }
    else { child = 3; a = ab; b = bc; c = ca; }
}

// Leaf triangle containing the upper-hemisphere direction d, and its corner vectors.
int vlfLocate(vec3 d, out vec3 a, out vec3 b, out vec3 c) {
    int q = d.y >= 0.0 ? (d.x > 0.0 ? 0 : 1) : (d.x < 0.0 ? 2 : 3);
    vec3 x = vec3(1, 0, 0), y = vec3(0, 1, 0);
    a = q == 0 ? x : q == 1 ? y : q == 2 ? -x : -y;
    b = q == 0 ? y : q == 1 ? -x : q == 2 ? -y : x;
    c = vec3(0, 0, 1);
    int index = q;
    for (int l = 0; l < uVlfParams.x; ++l) {
        int child;
        vlfChild(a, b, c, d, child);
        index = index * 4 + child;
    }
    return index;
}

// Bilinear value of face sf's tiles in subfield psf at world point p; w: weight found.
vec3 vlfCells(int sf, int psf, vec3 p, out float w) {
    ivec4 b0 = uVlfBlocks[2 * (sf * uVlfParams.w + psf)];
    ivec4 b1 = uVlfBlocks[2 * (sf * uVlfParams.w + psf) + 1];
    vec3 n = uVlfDirections[psf].xyz;
    // Subfield frame: the same construction as makeSubfieldFrame.
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float ka = -1.0 / (s + n.z);
    float kb = n.x * n.y * ka;
    vec3 u = normalize(vec3(1.0 + s * n.x * n.x * ka, s * kb, -s * n.x));
    vec3 v = cross(n, u);
    vec3 q = (p - uVlfFrame.xyz) / uVlfFrame.w;
    int N = uVlfParams.y, m = uVlfParams.z;
    vec2 c = (vec2(dot(q, u), dot(q, v)) + 1.0) * (0.5 * float(N)) - 0.5;
    ivec2 i0 = ivec2(floor(c));
    vec2 f = c - vec2(i0);
    vec3 sum = vec3(0.0);
    w = 0.0;
    for (int k = 0; k < 4; ++k) {
        ivec2 cell = i0 + ivec2(k & 1, k >> 1);
        float wk = ((k & 1) != 0 ? f.x : 1.0 - f.x) * ((k & 2) != 0 ? f.y : 1.0 - f.y);
        if (wk <= 0.0 || any(lessThan(cell, ivec2(0))) || any(greaterThanEqual(cell, ivec2(N))))
            continue;
        ivec2 tile = cell / m - b0.yz;
        if (any(lessThan(tile, ivec2(0))) || tile.x >= b0.w || tile.y >= b1.x) continue;
        int id = uVlfSlots[b1.y + tile.y * b0.w + tile.x];
        if (id < 0) continue;
        ivec2 atlas = ivec2(id % VLF_ATLAS_TILES, id / VLF_ATLAS_TILES) * m + cell % m;
        vec4 value = texelFetch(uVlfAtlas, atlas, 0);
        if (value.w <= 0.0) continue;
        sum += wk * value.rgb;
        w += wk;
    }
    return w > 0.0 ? sum * (uVlfCellScale / w) : vec3(0.0);
}

// Specular radiance, W/(m^2 sr), leaving world point p (shading normal n) towards the viewer.
vec3 vlfRadiance(vec3 p, vec3 n, vec3 toViewer) {
    if (uVlfFaceRange.y <= 0) return vec3(0.0);
    // The item's face whose plane holds p.
    int sf = -1;
    float best = 1e30;
    for (int k = 0; k < uVlfFaceRange.y; ++k) {
        vec4 plane = uVlfFaces[2 * (uVlfFaceRange.x + k)];
        float miss = abs(dot(plane.xyz, p) - plane.w) + (1.0 - dot(plane.xyz, n));
        if (miss < best) { best = miss; sf = uVlfFaceRange.x + k; }
    }
    vec3 fn = uVlfFaces[2 * sf].xyz;
    vec4 material = uVlfFaces[2 * sf + 1];
    vec3 dir = material.w > 0.5 ? 2.0 * dot(fn, toViewer) * fn - toViewer : toViewer;
    if (dot(fn, dir) <= 0.0) return vec3(0.0);
    float flip = dir.z < 0.0 ? -1.0 : 1.0;
    vec3 d = dir * flip;
    vec3 a, b, c;
    int t = vlfLocate(d, a, b, c);
    vec3 bary = vec3(dot(d, cross(b, c)), dot(a, cross(d, c)), dot(a, cross(b, d)));
    bary = max(bary, vec3(0.0));
    bary /= max(bary.x + bary.y + bary.z, 1e-20);
    ivec4 corners = uVlfTriangles[t];
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    for (int k = 0; k < 3; ++k) {
        int code = corners[k];
        int psf = code >> 1;
        float sign = ((code & 1) != 0 ? -1.0 : 1.0) * flip;
        if (bary[k] <= 0.0) continue;
        if (float(uVlfBlocks[2 * (sf * uVlfParams.w + psf)].x) != sign) continue;
        float w;
        vec3 value = vlfCells(sf, psf, p, w);
        if (w <= 0.0) continue;
        sum += bary[k] * value;
        wsum += bary[k];
    }
    if (wsum <= 0.0) return vec3(0.0);
    vec3 L = sum / wsum;
    return material.w > 0.5 ? material.rgb * L : L;
}
