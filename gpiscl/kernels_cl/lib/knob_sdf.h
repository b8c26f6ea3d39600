/* The authors' "material test knob" signed distance on the device: gpiscl/host/gp/knob.py
 * operation for operation, in double, so a bake here equals the numpy twin's float32
 * samples bit for bit (tests/test_device_bakes.py). FP_CONTRACT OFF: a fused multiply-add
 * rounds once where numpy rounds twice. The rotations' cosines and sines and pi / 3 come
 * from the host as exact hex literals (KNOB_* defines: cos(pi / 2) is 6.1e-17 in numpy,
 * not 0). No NaNs arise, so fmin / fmax agree with np.minimum / np.maximum. */
#pragma OPENCL FP_CONTRACT OFF

inline double knob_len2(double a, double b) { return sqrt(a * a + b * b); }
inline double knob_len3(double a, double b, double c) { return sqrt(a * a + b * b + c * c); }

/* _rot_x: right-handed rotation about +x by an angle of cosine c and sine s */
inline double3 knob_rot_x(double3 p, double c, double s)
{
    return (double3)(p.x, c * p.y - s * p.z, s * p.y + c * p.z);
}

inline double knob_sphere(double3 p, double r) { return knob_len3(p.x, p.y, p.z) - r; }

inline double knob_torus(double3 p, double big, double small)
{
    return knob_len2(knob_len2(p.x, p.z) - big, p.y) - small;
}

inline double knob_cone(double3 p, double c0, double c1)
{
    return c0 * knob_len2(p.x, p.y) + c1 * p.z;
}

inline double knob_capped_cylinder(double3 p, double h, double r)
{
    double qx = knob_len2(p.x, p.z) - h, qy = fabs(p.y) - r;
    return fmin(fmax(qx, qy), 0.0) + knob_len2(fmax(qx, 0.0), fmax(qy, 0.0));
}

inline double knob_tri_prism(double3 p, double h1, double h2)
{
    double3 q = fabs(p);
    return fmax(q.z - h2, fmax(0.866025 * q.x + 0.5 * p.y, -p.y) - 0.5 * h1);
}

inline double knob_clip01(double x) { return fmin(fmax(x, 0.0), 1.0); }

inline double knob_smooth_union(double d1, double d2, double k)
{
    double h = knob_clip01(0.5 + 0.5 * (d2 - d1) / k);
    return d2 + (d1 - d2) * h - k * h * (1.0 - h);
}

inline double knob_ssub(double d1, double d2, double k)
{
    double h = knob_clip01(0.5 - 0.5 * (d2 + d1) / k);
    return d2 + (-d1 - d2) * h + k * h * (1.0 - h);
}

inline double knob_base(double3 p)
{
    double3 up = (double3)(0.0, 0.9, 0.0);
    double b = knob_smooth_union(
        knob_cone(knob_rot_x(p + up, KNOB_COS_M90, KNOB_SIN_M90), KNOB_PI_3, KNOB_PI_3),
        knob_cone(knob_rot_x(p - up, KNOB_COS_P90, KNOB_SIN_P90), KNOB_PI_3, KNOB_PI_3), 0.02);
    b = 0.7 * fmax(b, knob_capped_cylinder(p, 1.1, 0.25));
    b = fmax(-knob_capped_cylinder(p, 0.6, 0.3), b);
    double3 shifted = p + (double3)(0.0, 0.0, -1.0);
    return fmax(-knob_tri_prism(knob_rot_x(shifted, KNOB_COS_P90, KNOB_SIN_P90), 1.2, 0.3), b);
}

inline double knob0(double3 p, int outer)
{
    double S = knob_sphere(p, 1.0);
    double C = knob_sphere(p - (double3)(0.0, 0.5, 0.5), 0.7);
    double E = knob_torus(knob_rot_x(p - (double3)(0.0, 0.2, 0.2), KNOB_COS_M45, KNOB_SIN_M45),
                          1.0, 0.05);
    double inner = knob_sphere(p, 0.75);
    double d = knob_ssub(C, S, 0.1);
    d = outer ? fmax(d, -inner) : fmin(d, inner);
    d = fmax(-E, d);
    return fmin(knob_ssub(S, knob_base(p - (double3)(0.0, -0.775, 0.0)), 0.1), d);
}

/* knob.FUNCTIONS by index: KNOB_FUNCTION_* of layout/constants.py */

inline double knob_function(int which, double3 p)
{
    if (which == KNOB_FUNCTION_KNOB_INNER) return knob_sphere(p, 0.6);
    return 0.8 * knob0(p / 0.8, which == KNOB_FUNCTION_KNOB_OUTER);
}
