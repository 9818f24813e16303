// Times the statics solve of John Till's public C++ tendon-robot example
// (ContinuumRobotExamples, 01_Statics/05_Tendon_Robot/Cpp/main.cpp): a Cosserat
// rod with tendons, classic RK4 on TILL_N grid points (TILL_N - 1 steps; the
// example uses 100) and the example's own Levenberg-Marquardt call with its
// finite-difference Jacobian, from its own zero guess. `run` builds this
// against the example's model (everything above its main(), extracted at
// build time, with `tau` made settable and the grid size a parameter).
//
// usage: till_bench <timed solves> <warm-up solves>
#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <vector>

#include "till_model.h"

namespace {

long passes = 0;

VectorXd counted(VectorXd guess) {
    ++passes;
    return shootingFunction(guess);
}

// The example's call and tolerances, unchanged.
template <VectorXd (*F)(VectorXd)>
VectorXd solve(const VectorXd &guess) {
    return solveLevenbergMarquardt<F>(guess, 1e-12, 500, 1e-2, 0.5, 1e-7, 1e-9);
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

template <class Body>
double median_ms(int timed, int warmup, Body body) {
    using clock = std::chrono::steady_clock;
    std::vector<double> ms;
    for (int i = 0; i < warmup + timed; ++i) {
        const auto t0 = clock::now();
        body(i);
        const auto t1 = clock::now();
        if (i >= warmup) ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    }
    return median(ms);
}

}  // namespace

int main(int argc, char **argv) {
    const int timed = argc > 1 ? std::atoi(argv[1]) : 31;
    const int warmup = argc > 2 ? std::atoi(argv[2]) : 5;
    const int steps = TILL_N - 1;
    std::cout.precision(10);

    const Vector6d zero = Vector6d::Zero();
    passes = 0;
    const VectorXd x = solve<counted>(zero);
    const Vector3d tip = Y.block<3, 1>(0, Y.cols() - 1);
    std::cout << "c++ steps=" << steps << " tau=(" << tau.transpose() << ") tip=(" << tip.transpose()
              << ") m, " << passes << " rod passes per cold solve\n";

    const double cold = median_ms(timed, warmup, [&](int) { solve<shootingFunction>(zero); });
    std::cout << "c++ steps=" << steps << " cold median " << cold << " ms\n";

    // Warm: from the previous solution, tendon 1 alternately +0.1 N and back.
    const VectorXd tau0 = tau;
    VectorXd prev = x;
    const double warm = median_ms(timed, warmup, [&](int i) {
        tau = tau0;
        if (i % 2 == 0) tau(0) += 0.1;
        prev = solve<shootingFunction>(prev);
    });
    std::cout << "c++ steps=" << steps << " warm median " << warm << " ms\n";
    return 0;
}
