// Irradiance from order-2 spherical harmonics of radiance (Ramamoorthi and Hanrahan 2001,
// "An efficient representation for irradiance environment maps", equation 13).
// Coefficient order: L00, L1-1, L10, L11, L2-2, L2-1, L20, L21, L22 over world (x, y, z).
vec3 shIrradiance(vec3 L[9], vec3 n) {
    const float c1 = 0.429043, c2 = 0.511664, c3 = 0.743125, c4 = 0.886227, c5 = 0.247708;
    float x = n.x, y = n.y, z = n.z;
    vec3 e = c1 * L[8] * (x * x - y * y) + c3 * L[6] * z * z + c4 * L[0] - c5 * L[6]
           + 2.0 * c1 * (L[4] * x * y + L[7] * x * z + L[5] * y * z)
           + 2.0 * c2 * (L[3] * x + L[1] * y + L[2] * z);
    return max(e, vec3(0.0)); // order-2 ringing can dip below zero
}
