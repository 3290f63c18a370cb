// An engine for `mjed-verify check` that computes force and stiffness with SOFA's own
// hyperelastic force fields: the SofaMJEDFEM plugin's MJEDTetrahedralForceField and SOFA's
// classical TetrahedronHyperelasticityFEMForceField and StandardTetrahedralFEMForceField.
//
// It never chooses a material or a parameter order: the Python side
// (conformance/adapters/sofa/engine.py) maps a kit case to SOFA's materialName and ParameterSet
// and passes them here, so the mapping lives in one place, the material declarations.
//
//   sofa_engine --forcefield mjed|hyperelasticity|standard --material NAME
//               --parameters "v1 v2 ..." [--regularize] CASE_INPUT_DIR OUTPUT_DIR
//   sofa_engine ... --time N --timing-json FILE CASE_INPUT_DIR OUTPUT_DIR
//
// Reads the case's case.txt and raw little-endian arrays (docs/conventions.md, "Exchange
// format"); writes force.f64 (f = -dPi/dx, as SOFA's addForce accumulates it) and the
// stiffness K = d2Pi/dx2 as COO triplets, exactly as SOFA's 3-argument addKToMatrix emits
// them with kFactor = -1 (SOFA's matrix is kFactor * df/dx and df/dx = -K). Nothing is
// symmetrised, summed or corrected here: what the checker judges is SOFA's output.
// With --time N it also times N repetitions of an explicit addForce, of an implicit addForce
// followed by addKToMatrix (force and assembled tangent, as an implicit solver with a direct
// linear solver calls them) and of one addDForce (a CG iteration), one thread, and writes the
// medians.

#include <SofaMJEDFEM/config.h>  // before the plugin's header: it uses the export macro
#include <SofaMJEDFEM/MJEDTetrahedralForceField.h>

#include <sofa/component/solidmechanics/fem/hyperelastic/StandardTetrahedralFEMForceField.h>
#include <sofa/component/solidmechanics/fem/hyperelastic/TetrahedronHyperelasticityFEMForceField.h>
#include <sofa/component/statecontainer/MechanicalObject.h>
#include <sofa/component/topology/container/dynamic/TetrahedronSetTopologyContainer.h>
#include <sofa/core/MechanicalParams.h>
#include <sofa/defaulttype/VecTypes.h>
#include <sofa/linearalgebra/BaseMatrix.h>
#include <sofa/simulation/Node.h>
#include <sofa/simulation/Simulation.h>
#include <sofa/simulation/graph/DAGSimulation.h>
#include <sofa/simulation/graph/init.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace
{
using sofa::defaulttype::Vec3Types;
using Coord = Vec3Types::Coord;
using VecCoord = Vec3Types::VecCoord;
using VecDeriv = Vec3Types::VecDeriv;

struct Failure : std::runtime_error
{
    using std::runtime_error::runtime_error;
};

// --- reading a case -------------------------------------------------------------------------

struct ArraySpec
{
    std::string file, dtype;
    std::vector<std::size_t> shape;
};

struct Case
{
    std::string id;
    std::size_t n_nodes = 0, n_cells = 0;
    std::map<std::string, ArraySpec> arrays;
    std::vector<double> points, positions;  // n x 3, row-major
    std::vector<std::int64_t> cells;        // m x 4
};

std::vector<char> read_file(const std::string& path, std::size_t expected_bytes)
{
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    if (!in) throw Failure("cannot open " + path);
    const auto size = static_cast<std::size_t>(in.tellg());
    if (size != expected_bytes)
        throw Failure(path + ": " + std::to_string(size) + " bytes, expected " +
                      std::to_string(expected_bytes));
    std::vector<char> data(size);
    in.seekg(0);
    in.read(data.data(), static_cast<std::streamsize>(size));
    return data;
}

template <class T>
std::vector<T> read_array(const std::string& dir, const ArraySpec& spec, const char* dtype,
                          std::size_t count)
{
    if (spec.dtype != dtype)
        throw Failure(spec.file + ": dtype " + spec.dtype + ", this engine reads " + dtype);
    std::size_t declared = 1;
    for (auto s : spec.shape) declared *= s;
    if (declared != count)
        throw Failure(spec.file + ": shape does not hold " + std::to_string(count) + " values");
    const auto bytes = read_file(dir + "/" + spec.file, count * sizeof(T));
    std::vector<T> values(count);
    std::copy(bytes.begin(), bytes.end(), reinterpret_cast<char*>(values.data()));
    return values;  // little-endian on every platform SOFA builds on (x86_64, aarch64)
}

Case read_case(const std::string& dir)
{
    std::ifstream in(dir + "/case.txt");
    if (!in) throw Failure("cannot open " + dir + "/case.txt");
    Case c;
    std::string line;
    while (std::getline(in, line))
    {
        std::istringstream words(line);
        std::string key;
        words >> key;
        if (key == "case") words >> c.id;
        else if (key == "n_nodes") words >> c.n_nodes;
        else if (key == "n_cells") words >> c.n_cells;
        else if (key == "array")
        {
            std::string name;
            ArraySpec spec;
            words >> name >> spec.file >> spec.dtype;
            std::size_t s;
            while (words >> s) spec.shape.push_back(s);
            c.arrays[name] = spec;
        }
    }
    for (const char* needed : {"points", "cells", "positions"})
        if (!c.arrays.count(needed)) throw Failure(dir + "/case.txt: no array " + needed);
    c.points = read_array<double>(dir, c.arrays["points"], "<f8", 3 * c.n_nodes);
    c.positions = read_array<double>(dir, c.arrays["positions"], "<f8", 3 * c.n_nodes);
    c.cells = read_array<std::int64_t>(dir, c.arrays["cells"], "<i8", 4 * c.n_cells);
    for (auto v : c.cells)
        if (v < 0 || static_cast<std::size_t>(v) >= c.n_nodes)
            throw Failure(dir + ": cell index " + std::to_string(v) + " outside the nodes");
    return c;
}

// --- SOFA's matrix interface, recorded as it is called ----------------------------------------

// Every add() SOFA makes is kept as one COO triplet, so the checker sees the assembled matrix
// exactly as SOFA's addKToMatrix built it (duplicates are summed by the reader).
class TripletMatrix final : public sofa::linearalgebra::BaseMatrix
{
public:
    explicit TripletMatrix(Index n) : n_(n) {}
    Index rowSize() const override { return n_; }
    Index colSize() const override { return n_; }
    SReal element(Index, Index) const override
    {
        throw Failure("TripletMatrix::element: not readable (SOFA only adds to it)");
    }
    void resize(Index r, Index) override { n_ = r; }
    void clear() override { rows.clear(), cols.clear(), values.clear(); }
    void set(Index, Index, double) override
    {
        throw Failure("TripletMatrix::set called: addKToMatrix was expected to only add");
    }
    void add(Index row, Index col, double v) override
    {
        rows.push_back(row), cols.push_back(col), values.push_back(v);
    }
    std::vector<std::int64_t> rows, cols;
    std::vector<double> values;

private:
    Index n_;
};

// --- the scene ---------------------------------------------------------------------------------

struct Options
{
    std::string forcefield, material, parameters, input, output, timing_json;
    bool regularize = false;
    int repeats = 0;
};

struct Scene
{
    sofa::simulation::Node::SPtr root;
    sofa::component::statecontainer::MechanicalObject<Vec3Types>::SPtr state;
    sofa::core::behavior::ForceField<Vec3Types>::SPtr forcefield;
};

template <class FF>
typename FF::SPtr make_forcefield(const Options& o)
{
    auto ff = sofa::core::objectmodel::New<FF>();
    auto set = [&](const char* name, const std::string& value) {
        auto* data = ff->findData(name);
        if (!data) throw Failure(std::string("force field has no Data '") + name + "'");
        if (!data->read(value))
            throw Failure(std::string("force field refused ") + name + "=" + value);
    };
    set("materialName", o.material);
    set("ParameterSet", o.parameters);
    if (o.regularize) set("matrixRegularization", "true");
    return ff;
}

std::string join(const std::vector<double>& v, std::size_t begin, std::size_t end)
{
    std::ostringstream s;
    s.precision(17);
    for (auto i = begin; i < end; ++i) s << (i > begin ? " " : "") << v[i];
    return s.str();
}

Scene build_scene(const Case& c, const Options& o)
{
    using namespace sofa;
    Scene s;
    s.root = simulation::getSimulation()->createNewGraph("root");
    auto topology = core::objectmodel::New<
        component::topology::container::dynamic::TetrahedronSetTopologyContainer>();
    std::ostringstream tets;
    for (std::size_t i = 0; i < c.cells.size(); ++i) tets << (i ? " " : "") << c.cells[i];
    topology->findData("position")->read(join(c.points, 0, c.points.size()));
    topology->findData("tetrahedra")->read(tets.str());
    s.root->addObject(topology);

    s.state = core::objectmodel::New<component::statecontainer::MechanicalObject<Vec3Types>>();
    s.state->findData("position")->read(join(c.points, 0, c.points.size()));
    s.state->findData("rest_position")->read(join(c.points, 0, c.points.size()));
    s.root->addObject(s.state);

    using namespace sofa::component::solidmechanics::fem::hyperelastic;
    if (o.forcefield == "mjed")
        s.forcefield = make_forcefield<component::forcefield::MJEDTetrahedralForceField<Vec3Types>>(o);
    else if (o.forcefield == "hyperelasticity")
        s.forcefield = make_forcefield<TetrahedronHyperelasticityFEMForceField<Vec3Types>>(o);
    else if (o.forcefield == "standard")
        s.forcefield = make_forcefield<StandardTetrahedralFEMForceField<Vec3Types>>(o);
    else
        throw Failure("unknown --forcefield " + o.forcefield +
                      " (mjed, hyperelasticity or standard)");
    s.root->addObject(s.forcefield);
    simulation::node::initRoot(s.root.get());
    return s;
}

void set_positions(Scene& s, const std::vector<double>& x)
{
    auto pos = sofa::helper::getWriteOnlyAccessor(*s.state->write(sofa::core::vec_id::write_access::position));
    for (std::size_t a = 0; a < pos.size(); ++a)
        pos[a] = Coord(x[3 * a], x[3 * a + 1], x[3 * a + 2]);
}

// implicit: as an implicit solver calls it. SOFA's StandardTetrahedralFEMForceField builds its
// tangent inside addForce only then, and addKToMatrix assembles what addForce left.
VecDeriv force(Scene& s, bool implicit = true)
{
    sofa::core::MechanicalParams mparams;
    mparams.setImplicit(implicit);
    sofa::core::objectmodel::Data<VecDeriv> f;
    f.setValue(VecDeriv(s.state->getSize(), Vec3Types::Deriv()));
    s.forcefield->addForce(&mparams, f, *s.state->read(sofa::core::vec_id::read_access::position),
                           *s.state->read(sofa::core::vec_id::read_access::velocity));
    return f.getValue();
}

void stiffness(Scene& s, TripletMatrix& k)
{
    unsigned int offset = 0;
    s.forcefield->addKToMatrix(&k, -1.0, offset);  // -1 * df/dx = K, the Hessian
}

void write_raw(const std::string& path, const void* data, std::size_t bytes)
{
    std::ofstream out(path, std::ios::binary);
    out.write(static_cast<const char*>(data), static_cast<std::streamsize>(bytes));
    if (!out) throw Failure("cannot write " + path);
}

double median(std::vector<double> v)
{
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

void time_calls(Scene& s, const Case& c, const Options& o)
{
    using clock = std::chrono::steady_clock;
    std::vector<double> t_force, t_stiffness, t_dforce;
    sofa::core::MechanicalParams mparams;
    mparams.setKFactor(1.0);
    sofa::core::objectmodel::Data<VecDeriv> df, dx;
    VecDeriv probe(c.n_nodes);
    for (std::size_t a = 0; a < c.n_nodes; ++a) probe[a] = Vec3Types::Deriv(1e-3, -2e-3, 1.5e-3);
    dx.setValue(probe);
    TripletMatrix k(static_cast<sofa::Index>(3 * c.n_nodes));
    for (int r = 0; r < o.repeats; ++r)
    {
        set_positions(s, c.positions);
        auto t0 = clock::now();
        force(s, false);  // an explicit solver's call: the force alone
        auto t1 = clock::now();
        force(s, true);  // an implicit solver's: the force, and the tangent marked out of date
        k.clear();
        stiffness(s, k);  // (re)builds the tangent where it is lazy, then assembles it
        auto t2 = clock::now();
        df.setValue(VecDeriv(c.n_nodes, Vec3Types::Deriv()));
        s.forcefield->addDForce(&mparams, df, dx);
        auto t3 = clock::now();
        t_force.push_back(std::chrono::duration<double>(t1 - t0).count());
        t_stiffness.push_back(std::chrono::duration<double>(t2 - t1).count());  // f + K
        t_dforce.push_back(std::chrono::duration<double>(t3 - t2).count());
    }
    std::ofstream out(o.timing_json);
    out.precision(9);
    out << "{\"forcefield\": \"" << o.forcefield << "\", \"material\": \"" << o.material
        << "\", \"n_cells\": " << c.n_cells << ", \"n_nodes\": " << c.n_nodes
        << ", \"repeats\": " << o.repeats << ", \"add_force_s\": " << median(t_force)
        << ", \"implicit_add_force_and_k_to_matrix_s\": " << median(t_stiffness)
        << ", \"add_dforce_s\": " << median(t_dforce) << "}\n";
    if (!out) throw Failure("cannot write " + o.timing_json);
}

Options parse(int argc, char** argv)
{
    Options o;
    std::vector<std::string> positional;
    for (int i = 1; i < argc; ++i)
    {
        std::string a = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) throw Failure(a + " needs a value");
            return argv[++i];
        };
        if (a == "--forcefield") o.forcefield = value();
        else if (a == "--material") o.material = value();
        else if (a == "--parameters") o.parameters = value();
        else if (a == "--regularize") o.regularize = true;
        else if (a == "--time") o.repeats = std::stoi(value());
        else if (a == "--timing-json") o.timing_json = value();
        else if (a.rfind("--", 0) == 0) throw Failure("unknown option " + a);
        else positional.push_back(a);
    }
    if (positional.size() != 2 || o.forcefield.empty() || o.material.empty() ||
        o.parameters.empty())
        throw Failure(
            "usage: sofa_engine --forcefield mjed|hyperelasticity|standard --material NAME "
            "--parameters \"v1 v2 ...\" [--regularize] [--time N --timing-json FILE] "
            "CASE_INPUT_DIR OUTPUT_DIR");
    if (o.repeats > 0 && o.timing_json.empty()) throw Failure("--time needs --timing-json");
    o.input = positional[0], o.output = positional[1];
    return o;
}

}  // namespace

int main(int argc, char** argv)
{
    try
    {
        const Options o = parse(argc, argv);
        const Case c = read_case(o.input);
        sofa::simulation::graph::init();
        Scene s = build_scene(c, o);
        if (s.state->getSize() != c.n_nodes)
            throw Failure("SOFA's state holds " + std::to_string(s.state->getSize()) +
                          " nodes, the case " + std::to_string(c.n_nodes));

        set_positions(s, c.positions);
        const VecDeriv f = force(s);
        TripletMatrix k(static_cast<sofa::Index>(3 * c.n_nodes));
        stiffness(s, k);

        std::vector<double> flat(3 * c.n_nodes);
        for (std::size_t a = 0; a < c.n_nodes; ++a)
            for (int d = 0; d < 3; ++d) flat[3 * a + d] = f[a][d];
        write_raw(o.output + "/force.f64", flat.data(), flat.size() * sizeof(double));
        write_raw(o.output + "/stiffness_rows.i64", k.rows.data(), k.rows.size() * 8);
        write_raw(o.output + "/stiffness_cols.i64", k.cols.data(), k.cols.size() * 8);
        write_raw(o.output + "/stiffness_values.f64", k.values.data(), k.values.size() * 8);
        if (o.repeats > 0) time_calls(s, c, o);
        sofa::simulation::node::unload(s.root);
        return 0;
    }
    catch (const std::exception& e)
    {
        std::cerr << "sofa_engine: " << e.what() << "\n";
        return 1;
    }
}
