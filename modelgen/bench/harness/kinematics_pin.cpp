/* Pinocchio's side of bench/kinematics.py: one frame's Jacobian
 * (computeFrameJacobian, LOCAL_WORLD_ALIGNED) or the centroidal map
 * (computeCentroidalMap) of a robot rebuilt from a text description that the
 * script writes from Pinocchio's own URDF model (so no URDF parser is needed
 * here).  Usage:
 *   kinematics_pin MODEL.txt          prints the best time per call [s] and loops
 *   kinematics_pin MODEL.txt K        K calls untimed, then a sink (for callgrind)
 * MODEL.txt: "nq nv njoints" then per joint "kind parent  R(9) p(3)  m c(3)
 * I(xx xy yy xz yz zz)  [axis(3)]", then "frame parent R(9) p(3)" or "centroidal",
 * then "q" and nq values. */
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <iostream>
#include <string>
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/centroidal.hpp>

using namespace pinocchio;

static double now()
{
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static SE3 read_se3(std::istream &in)
{
    Eigen::Matrix3d R;
    Eigen::Vector3d p;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            in >> R(i, j);
    in >> p[0] >> p[1] >> p[2];
    return SE3(R, p);
}

int main(int argc, char **argv)
{
    std::ifstream in(argv[1]);
    int nq, nv, nj;
    in >> nq >> nv >> nj;
    Model model;
    for (int i = 1; i < nj; ++i) {
        std::string kind;
        int parent;
        in >> kind >> parent;
        SE3 placement = read_se3(in);
        double m, c[3], I[6];
        in >> m >> c[0] >> c[1] >> c[2];
        for (double &x : I)
            in >> x;
        Eigen::Vector3d axis;
        JointIndex id;
        const std::string name = "j" + std::to_string(i);
        if (kind == "RX") id = model.addJoint(parent, JointModelRX(), placement, name);
        else if (kind == "RY") id = model.addJoint(parent, JointModelRY(), placement, name);
        else if (kind == "RZ") id = model.addJoint(parent, JointModelRZ(), placement, name);
        else if (kind == "PX") id = model.addJoint(parent, JointModelPX(), placement, name);
        else if (kind == "PY") id = model.addJoint(parent, JointModelPY(), placement, name);
        else if (kind == "PZ") id = model.addJoint(parent, JointModelPZ(), placement, name);
        else if (kind == "FF") id = model.addJoint(parent, JointModelFreeFlyer(), placement, name);
        else if (kind == "RU" || kind == "PU") {
            in >> axis[0] >> axis[1] >> axis[2];
            id = kind == "RU" ? model.addJoint(parent, JointModelRevoluteUnaligned(axis), placement, name)
                              : model.addJoint(parent, JointModelPrismaticUnaligned(axis), placement, name);
        } else {
            std::fprintf(stderr, "unknown joint kind %s\n", kind.c_str());
            return 2;
        }
        Symmetric3 sym(I[0], I[1], I[2], I[3], I[4], I[5]);
        model.appendBodyToJoint(id, Inertia(m, Eigen::Vector3d(c[0], c[1], c[2]), sym));
    }
    std::string what;
    in >> what;
    FrameIndex frame = 0;
    if (what == "frame") {
        int parent;
        in >> parent;
        SE3 placement = read_se3(in);
        frame = model.addFrame(Frame("tool", parent, placement, OP_FRAME));
        in >> what;
    } else {
        in >> what;      /* "centroidal", then "q" */
    }
    Eigen::VectorXd q0(nq), q(nq);
    for (int i = 0; i < nq; ++i)
        in >> q0[i];
    q = q0;
    Data data(model);
    Data::Matrix6x J = Data::Matrix6x::Zero(6, model.nv);
    const bool centroidal = frame == 0;
    double sink = 0;
    /* each call's q depends on the previous result, as in modelgen's harness */
    auto run = [&](long loops) {
        const double start = now();
        for (long k = 0; k < loops; ++k) {
            const int j = (int)(k % nq);
            if (centroidal) {
                q[j] = q0[j] + 1e-12 * data.Ag(5, model.nv - 1 - j % model.nv);
                computeCentroidalMap(model, data, q);
                sink += data.Ag(5, model.nv - 1);
            } else {
                q[j] = q0[j] + 1e-12 * J(5, model.nv - 1 - j % model.nv);
                computeFrameJacobian(model, data, q, frame, LOCAL_WORLD_ALIGNED, J);
                sink += J(5, model.nv - 1);
            }
        }
        return now() - start;
    };
    if (argc == 3) {
        run(std::atol(argv[2]));
        std::printf("%.17g\n", sink);
        return 0;
    }
    long loops = 1;
    while (run(loops) < 0.05)
        loops *= 2;
    double best = 1e300;
    for (int r = 0; r < 5; ++r) {
        const double t = run(loops) / (double)loops;
        best = t < best ? t : best;
    }
    std::printf("%.6e %ld %.17g\n", best, loops, sink);
    return 0;
}
