#include <qpOASES.hpp>
#include <string.h>
#include <time.h>
#include <new>

using namespace qpOASES;

namespace {
struct Handle {
    SQProblem qp;
    Options options;
    int nV, nC;
    double* d;
    int* iv;
    bool initialised;
    Handle(int nV_, int nC_, double* d_, int* iv_)
        : qp(nV_, nC_), nV(nV_), nC(nC_), d(d_), iv(iv_), initialised(false) {}
};
inline double now() { timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
int set_option(Options& o, const char* name, double v) {
@SETTERS@
    return -1;
}
/* qpOASES' destructor makes its global messages visible again: hidden here once more, as every
   solver of the shim has them (printLevel PL_NONE). */
void hide_messages() {
    MessageHandling* m = getGlobalMessageHandler();
    m->setErrorVisibilityStatus(VS_HIDDEN);
    m->setWarningVisibilityStatus(VS_HIDDEN);
    m->setInfoVisibilityStatus(VS_HIDDEN);
}
}

extern "C" {
void* qpb_new(int nV, int nC, double* d, int* iv, int preset) {
    Handle* h = new (std::nothrow) Handle(nV, nC, d, iv);
    if (!h) return 0;
    if (preset == 1) h->options.setToMPC();
    else if (preset == 2) h->options.setToReliable();
    else if (preset == 3) h->options.setToFast();
    else h->options.setToDefault();
    h->options.printLevel = PL_NONE;
    h->qp.setOptions(h->options);
    return h;
}
int qpb_set_option(void* p, const char* name, double v) {
    Handle* h = static_cast<Handle*>(p);
    if (set_option(h->options, name, v)) return -1;
    h->options.printLevel = PL_NONE;
    h->options.ensureConsistency();
    h->qp.setOptions(h->options);
    return 0;
}
int qpb_known_option(const char* name) { Options o; return set_option(o, name, 0.0) == 0; }
void qpb_free(void* p) { delete static_cast<Handle*>(p); hide_messages(); }
/* The SQProblem made afresh with the handle's options, as qpb_new left it: the next
   qpb_solve calls init() on a solver with no history. */
void qpb_renew(void* p) {
    Handle* h = static_cast<Handle*>(p);
    h->initialised = false;
    h->qp.~SQProblem();
    new (&h->qp) SQProblem(h->nV, h->nC);
    h->qp.setOptions(h->options);
}
const char* qpb_message(int rv) {
    return MessageHandling::getErrorCodeMessage((returnValue) rv);
}
int qpb_solve(void* p) {
    Handle* h = static_cast<Handle*>(p);
    const int n = h->nV, m = h->nC;
    double* d = h->d;
    int* iv = h->iv;
    double* H = d;
    double* g = H + n * n;
    double* A = g + n;
    double* lb = A + m * n;
    double* ub = lb + n;
    double* lbA = ub + n;
    double* ubA = lbA + m;
    double* x = ubA + m;
    double* y = x + n;
    double* s = y + n + m;
    for (int j = 0; j < 2 * n + 2 * m; ++j) {
        if (lb[j] < -INFTY) lb[j] = -INFTY;
        else if (lb[j] > INFTY) lb[j] = INFTY;
    }
    int nWSR = iv[0];
    double cpu = s[1];
    double t0 = now();
    returnValue rv = h->initialised
        ? h->qp.hotstart(H, g, A, lb, ub, m ? lbA : 0, m ? ubA : 0, nWSR, &cpu)
        : h->qp.init(H, g, A, lb, ub, m ? lbA : 0, m ? ubA : 0, nWSR, &cpu);
    s[2] = now() - t0;
    s[3] = cpu;
    iv[2] = nWSR;
    iv[3] = (int) rv;
    int st;
    if (rv == SUCCESSFUL_RETURN) st = 0;
    else if (h->qp.isInfeasible() || rv == RET_INIT_FAILED_INFEASIBILITY
             || rv == RET_HOTSTART_STOPPED_INFEASIBILITY) st = -2;
    else if (h->qp.isUnbounded() || rv == RET_INIT_FAILED_UNBOUNDEDNESS
             || rv == RET_HOTSTART_STOPPED_UNBOUNDEDNESS) st = -3;
    else if (rv == RET_MAX_NWSR_REACHED) st = (nWSR < iv[0]) ? 2 : 1;
    else st = -1;
    iv[4] = st;
    if (st == 0) {
        h->qp.getPrimalSolution(x);
        h->qp.getDualSolution(y);
        for (int j = 0; j < n + m; ++j) y[j] = -y[j];  /* qpsolvers' sign */
        s[0] = h->qp.getObjVal();
        h->initialised = true;
    } else {
        h->initialised = false;
    }
    return st;
}
}
