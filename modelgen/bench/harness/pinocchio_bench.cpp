// Timing harness for Pinocchio's ABA, CRBA + Cholesky, rnea and
// computeABADerivatives, built by
// modelgen.bench.harnesses.build_pinocchio_harness with -DMIN_SECONDS and -DREPEATS.
// Usage: pin_bench tree.txt, the file holding the number of joints,
// then per joint (parents first) "parent(0 = ground, else 1-based) kind(0, 1, 2 =
// revolute about z, y, x; 3 = free flyer) R(9, row-major, joint frame in the
// parent's) p(3) mass c(3) Ixx Iyy Izz Ixy Ixz Iyz (about c)", then g, then x0
// (q then v: nq + nv numbers, a free flyer's q as x y z qx qy qz qw).
// Prints: aba_s crba_s, then q_ddot at x0 by each, then rnea's tau at x0 and the
// accelerations ACC(i).  pin_bench tree.txt WHICH prints the time of ABA (WHICH 0),
// the CRBA path (1), rnea (2) or computeABADerivatives at tau = 0 (3) alone, and for
// WHICH 3 then d q_ddot / d q and d q_ddot / d v at x0 (row-major, a line each);
// pin_bench tree.txt WHICH K instead calls it K times untimed (for callgrind).
#include <cstdlib>
#include <cstdio>
#include <ctime>
#include <string>
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/cholesky.hpp>
#include <pinocchio/algorithm/aba-derivatives.hpp>

static double now() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static pinocchio::Model model;
static double x0[2048];

// the accelerations given to rnea (bench/inverse_dynamics.py uses the same)
#define ACC(i) (0.3 * (double)((i) % 3) - 0.2)

static void crba_path(pinocchio::Data &data, const Eigen::VectorXd &q, const Eigen::VectorXd &v,
                      const Eigen::VectorXd &tau, Eigen::VectorXd &qdd) {
    pinocchio::crba(model, data, q);
    pinocchio::nonLinearEffects(model, data, q, v);
    qdd = tau - data.nle;
    pinocchio::cholesky::decompose(model, data);   // reads the upper triangle of M
    pinocchio::cholesky::solve(model, data, qdd);
}

template <int WHICH> static double run(pinocchio::Data &data, long loops, double &sink) {
    const int n = model.nv;
    Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(x0, model.nq);
    Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(x0 + model.nq, n);
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(n), qdd = Eigen::VectorXd::Zero(n);
    Eigen::VectorXd acc(n);
    for (int i = 0; i < n; ++i) acc[i] = ACC(i);
    const double start = now();
    for (long k = 0; k < loops; ++k) {
        const int j = (int)(k % n);
        q[j] = x0[j] + 1e-9 * qdd[n - 1 - j];
        if (WHICH == 0) {
            pinocchio::aba(model, data, q, v, tau);
            qdd = data.ddq;
        } else if (WHICH == 1) {
            crba_path(data, q, v, tau, qdd);
        } else if (WHICH == 2) {
            pinocchio::rnea(model, data, q, v, acc);
            qdd = data.tau;
        } else {
            // the next call depends on the derivatives, as in modelgen's harness
            pinocchio::computeABADerivatives(model, data, q, v, tau);
            const int next = (int)((k + 1) % n);     // the entry the next call reads
            qdd[n - 1 - next] = data.ddq_dq(n - 1, next);
        }
        sink += qdd[n - 1];
    }
    return now() - start;
}

template <int WHICH> static double best(pinocchio::Data &data, double &sink) {
    long loops = 1;
    while (run<WHICH>(data, loops, sink) < MIN_SECONDS) loops *= 2;
    double b = 1e300;
    for (int r = 0; r < REPEATS; ++r) {
        const double t = run<WHICH>(data, loops, sink) / (double)loops;
        if (t < b) b = t;
    }
    return b;
}

static int read_chain(const char *path) {
    std::FILE *f = std::fopen(path, "r");
    int n = 0;
    if (!f || std::fscanf(f, "%d", &n) != 1 || n < 1 || n > 1024) return 0;
    for (int i = 0; i < n; ++i) {
        int parent, axis;
        double v[22];
        if (std::fscanf(f, "%d %d", &parent, &axis) != 2 || parent < 0 || parent > i)
            return 0;
        for (int k = 0; k < 22; ++k)
            if (std::fscanf(f, "%lf", &v[k]) != 1) return 0;
        Eigen::Matrix3d R;
        R << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
        const pinocchio::SE3 placement(R, Eigen::Vector3d(v[9], v[10], v[11]));
        const std::string name = "q" + std::to_string(i + 1);
        pinocchio::Model::JointIndex id;
        const pinocchio::Model::JointIndex p = (pinocchio::Model::JointIndex)parent;
        if (axis == 0)
            id = model.addJoint(p, pinocchio::JointModelRZ(), placement, name);
        else if (axis == 1)
            id = model.addJoint(p, pinocchio::JointModelRY(), placement, name);
        else if (axis == 2)
            id = model.addJoint(p, pinocchio::JointModelRX(), placement, name);
        else
            id = model.addJoint(p, pinocchio::JointModelFreeFlyer(), placement, name);
        Eigen::Matrix3d I;
        I << v[16], v[19], v[20], v[19], v[17], v[21], v[20], v[21], v[18];
        model.appendBodyToJoint(id, pinocchio::Inertia(v[12], Eigen::Vector3d(v[13], v[14], v[15]),
                                                       I), pinocchio::SE3::Identity());
    }
    double g;
    if (std::fscanf(f, "%lf", &g) != 1) return 0;
    model.gravity.linear(Eigen::Vector3d(0.0, 0.0, -g));
    if (model.nq + model.nv > 2048) return 0;
    for (int i = 0; i < model.nq + model.nv; ++i)
        if (std::fscanf(f, "%lf", &x0[i]) != 1) return 0;
    std::fclose(f);
    return n;
}

// d q_ddot / d q, then d q_ddot / d v, at x0 and tau = 0, row-major, a line each
static void print_aba_derivatives(pinocchio::Data &data) {
    const int n = model.nv;
    const Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(x0, model.nq);
    const Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(x0 + model.nq, n);
    pinocchio::computeABADerivatives(model, data, q, v, Eigen::VectorXd::Zero(n));
    const auto print = [n](const auto &m) {
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) std::printf("%.17g ", m(i, j));
        std::printf("\n");
    };
    print(data.ddq_dq);
    print(data.ddq_dv);
}

int main(int argc, char **argv) {
    if (argc < 2 || argc > 4 || !read_chain(argv[1])) {
        std::fprintf(stderr, "usage: pin_bench chain.txt (see the source)\n");
        return 2;
    }
    pinocchio::Data data(model);
    double sink = 0.0;
    if (argc >= 3) {
        const int which = std::atoi(argv[2]);
        if (argc == 3) {
            const double t = which == 0   ? best<0>(data, sink)
                             : which == 1 ? best<1>(data, sink)
                             : which == 2 ? best<2>(data, sink)
                                          : best<3>(data, sink);
            std::printf("%.9e %.3g\n", t, sink * 0.0);
            if (which == 3) print_aba_derivatives(data);
            return 0;
        }
        const long loops = std::atol(argv[3]);
        if (which == 0)
            run<0>(data, loops, sink);
        else if (which == 1)
            run<1>(data, loops, sink);
        else if (which == 2)
            run<2>(data, loops, sink);
        else
            run<3>(data, loops, sink);
        std::printf("%.17g\n", sink);
        return 0;
    }
    const double aba = best<0>(data, sink), crba = best<1>(data, sink);
    const int n = model.nv;
    Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(x0, model.nq);
    Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(x0 + model.nq, n);
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(n), qdd(n);
    std::printf("%.9e %.9e %.3g\n", aba, crba, sink * 0.0);
    pinocchio::aba(model, data, q, v, tau);
    for (int i = 0; i < n; ++i) std::printf("%.17g ", data.ddq[i]);
    std::printf("\n");
    crba_path(data, q, v, tau, qdd);
    for (int i = 0; i < n; ++i) std::printf("%.17g ", qdd[i]);
    std::printf("\n");
    Eigen::VectorXd acc(n);
    for (int i = 0; i < n; ++i) acc[i] = ACC(i);
    pinocchio::rnea(model, data, q, v, acc);
    for (int i = 0; i < n; ++i) std::printf("%.17g ", data.tau[i]);
    std::printf("\n");
    return 0;
}
