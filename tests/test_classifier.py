"""LDA decisions vs scikit-learn, post-processing and proportional output by hand, model files."""
from __future__ import annotations

import json

import numpy as np
import pytest
from sklearn.decomposition import PCA
from sklearn.discriminant_analysis import LinearDiscriminantAnalysis
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from threadpoolctl import threadpool_limits

from bomi.chain import MotionCopies, prepare, recorded_priors, training_windows
from bomi.classifier import (AmplitudeRange, MajorityVote, PipelineParameters, PostProcessing, amplitude_ranges, class_amplitude,
                             RANK_TOLERANCE, classify_windows, fit_pipeline, fit_pipelines, gamma, majority_vote, numerical_rank, posteriors,
                             proportional, reject, sample_amplitude)
from tasks.cli import main
from bomi.errors import BomiError
from bomi.model_io import FORMAT_VERSION, load_model, save_model
from helpers import assert_agree


def test_posteriors_are_sklearns(p1_days, p1_profile, day1_fv1_model):
    """The exported linear discriminant reproduces the fitted sklearn estimator on real data."""
    windows, _ = training_windows(p1_days[1], day1_fv1_model.spec, p1_profile.neutral_samples,
                                  MotionCopies.of(p1_profile))   # P1's turned shoulder copies too
    lda = fit_pipeline(windows.features, windows.labels, day1_fv1_model.shrinkage,
                       recorded_priors(windows.labels, windows.recorded))
    test = prepare(p1_days[2], day1_fv1_model.spec, p1_profile.neutral_samples).features
    assert np.allclose(posteriors(day1_fv1_model, test), lda.predict_proba(test), rtol=0, atol=1e-12)
    assert np.array_equal(classify_windows(day1_fv1_model, test).raw, lda.predict(test))


def test_rejection_and_vote_by_hand():
    labels = np.array([1, 1, 2, 3, 3, 1])
    confidence = np.array([0.99, 0.5, 0.95, 0.7, 0.99, 0.9])
    assert reject(labels, confidence, None).tolist() == labels.tolist()
    assert reject(labels, confidence, 0.9).tolist() == [1, 0, 2, 0, 3, 1]
    # window of 3: [1] [1,1] [1,1,2] [1,2,3]->tie, latest 3 [2,3,3] [3,3,1]
    assert majority_vote(labels, 3).tolist() == [1, 1, 1, 3, 3, 3]
    assert majority_vote(labels, 1).tolist() == labels.tolist()
    vote = MajorityVote(2)
    assert [vote.push(v) for v in (4, 5, 5, 4)] == [4, 5, 5, 4]


def one_feature(lda_coef, lda_intercept, mean=0.0, scale=1.0, direction=1.0) -> PipelineParameters:
    """A pipeline over one feature: (x - mean) / scale, then PCA's single direction (+-1)."""
    one = np.ones(1)
    return PipelineParameters(mean * one, scale * one, np.zeros(1), direction * np.ones((1, 1)),
                              np.array(lda_coef, dtype=float)[:, None], np.array(lda_intercept, dtype=float))


def test_pipeline_as_one_discriminant_by_hand():
    # x -> (x - 2) / 4 -> times -1 (PCA's direction) -> scores 6 (2 - x) / 4 + 1 = -1.5 x + 4
    coef, intercept = one_feature([6.0, 0.0, -6.0], [1.0, 0.0, -1.0], mean=2.0, scale=4.0, direction=-1.0).linear()
    np.testing.assert_allclose(coef, [[-1.5], [0.0], [1.5]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(intercept, [4.0, 0.0, -4.0], rtol=0, atol=1e-15)


def test_decide_applies_rejection_before_vote():
    from bomi.classifier import Model
    from bomi.features import FeatureSpec
    model = Model(classes=np.array([0, 1, 2]), parameters=one_feature([0.0, 1.0, -1.0], [0.0, 0.0, 0.0]),
                  spec=FeatureSpec("FV1", (1,), window=1), amplitude={})
    x = np.array([[5.0], [0.1], [5.0], [-5.0]])
    d = classify_windows(model, x, PostProcessing(rejection_threshold=0.9, vote_length=1))
    assert d.raw.tolist() == [1, 1, 1, 2] and d.rejected.tolist() == [False, True, False, False]
    assert d.labels.tolist() == [1, 0, 1, 2]
    assert classify_windows(model, x, PostProcessing(rejection_threshold=0.9, vote_length=3)).labels.tolist() == [1, 0, 1, 2]


def test_proportional_output_by_hand():
    assert gamma(np.array([3.0, 0]), np.array([4.0, 0]), np.array([12.0, 0])).tolist() == [13.0, 0.0]
    assert gamma(-3.0, 4.0, 12.0) == 13.0
    r = AmplitudeRange(node=1, gamma_min=5.0, gamma_max=25.0)
    assert proportional(15.0, r) == 0.5
    assert proportional(40.0, r) == 1.0 and proportional(5.0, r) == 0.0
    assert proportional(1.0, r) == 0.0           # below the least calibrated motion: no speed
    assert proportional(7.0, None) == 0.0        # neutral class
    labels = np.array([0, 1, 1, 2, 2, 2])
    pitch_only = lambda values: np.c_[values, np.zeros((len(values), 2))]  # noqa: E731  gamma = |pitch|
    ranges = amplitude_ranges({1: pitch_only([9, 3, 8, 0, 0, 0.0]), 2: pitch_only([9, 9, 9, 4, 6, -5.0])}, labels,
                              {1: 1, 2: 2})
    assert ranges == {1: AmplitudeRange(1, 3.0, 8.0), 2: AmplitudeRange(2, 4.0, 6.0)}


def test_amplitude_along_the_class_direction_by_hand():
    # class 1 held at (3, 4, 0) and (6, 8, 0) deg: mean direction (0.6, 0.8, 0), amplitudes 5 and 10
    labels = np.array([0, 1, 1])
    angles = {1: np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [6.0, 8.0, 0.0]])}
    (r,) = amplitude_ranges(angles, labels, {1: 1}, kind="along_class").values()
    assert r.direction == pytest.approx((0.6, 0.8, 0.0)) and (r.gamma_min, r.gamma_max) == pytest.approx((5.0, 10.0))
    # a motion elsewhere: gamma 10 (the paper's amplitude would say full speed), along the class 0.6 x -8 = -4.8
    across = np.array([0.0, 0.0, 10.0]), np.array([-8.0, 6.0, 0.0])
    assert class_amplitude(across[0], r.direction) == pytest.approx(0.0)
    assert class_amplitude(across[1], r.direction) == pytest.approx(0.6 * -8 + 0.8 * 6)
    assert class_amplitude(across[1], None) == pytest.approx(10.0)
    assert proportional(float(class_amplitude(np.array([4.5, 6.0, 0.0]), r.direction)), r) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="amplitude kind"):
        amplitude_ranges(angles, labels, {1: 1}, kind="norm")


def test_a_samples_amplitude_on_floats_agrees_with_the_arrays():
    """The streaming chain's ``sample_amplitude`` (Python floats) gives what ``class_amplitude`` gives on
    the sample's (3,) array, to 4 ulps (a dot product or a norm, which BLAS may fuse on one CPU and
    not on another): gamma and the component along a unit direction, on angles of every size and sign,
    zeros giving zero; by hand on the 3-4-5 sample."""
    assert sample_amplitude(3.0, 4.0, 0.0, None) == 5.0
    assert sample_amplitude(3.0, 4.0, 0.0, (0.6, 0.8, 0.0)) == 0.6 * 3.0 + 0.8 * 4.0
    rng = np.random.default_rng(11)
    angles = rng.normal(size=(20000, 3)) * rng.choice([1e-3, 1.0, 30.0, 170.0], size=(20000, 1))
    angles[:50] = np.where(rng.uniform(size=(50, 3)) < 0.5, -0.0, 0.0)
    directions = rng.normal(size=(40, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for direction in [None, *(tuple(d) for d in directions.tolist())]:
        for row in angles[rng.choice(len(angles), 2000)].tolist() + angles[:50].tolist():
            expected = float(class_amplitude(np.array(row), direction))
            got = sample_amplitude(*row, direction)
            assert type(got) is float
            assert_agree(got, expected, scale=max(abs(expected), *map(abs, row)))
            assert (got == 0.0) == (expected == 0.0), (row, direction)


def test_post_processing_validation():
    with pytest.raises(ValueError):
        PostProcessing(rejection_threshold=1.5)
    with pytest.raises(ValueError):
        PostProcessing(vote_length=0)


@pytest.mark.parametrize("suffix", [".json", ".npz"])
def test_saved_model_predicts_exactly_like_trained(tmp_path, suffix, p1_days, p1_profile, day1_fv3_model):
    path = tmp_path / f"model{suffix}"
    save_model(path, day1_fv3_model)
    loaded = load_model(path)
    x = prepare(p1_days[3], loaded.spec, p1_profile.neutral_samples).features
    assert np.array_equal(posteriors(loaded, x), posteriors(day1_fv3_model, x))
    assert loaded.spec == day1_fv3_model.spec and loaded.amplitude == day1_fv3_model.amplitude
    assert loaded.post == day1_fv3_model.post and loaded.shrinkage == day1_fv3_model.shrinkage


def corrupt(tmp_path, day1_fv1_model, edit):
    path = tmp_path / "m.json"
    save_model(path, day1_fv1_model)
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.update(version=FORMAT_VERSION + 1), f"format version {FORMAT_VERSION + 1}"),
    (lambda d: d.update(format="other"), "format is 'other'"),
    (lambda d: d.pop("lda_coef"), "missing array(s) lda_coef"),
    (lambda d: d.update(lda_coef=d["lda_coef"][:-1]), "lda_coef has shape"),
    (lambda d: d.update(scaler_scale=[-v for v in d["scaler_scale"]]), "scaler_scale must be positive"),
    (lambda d: d.update(version=2), "model format version 2 (an LDA on unstandardised features); this program reads "
                                    f"version {FORMAT_VERSION}: retrain it with bomi train"),
    (lambda d: d["features"].update(kind="FV9"), "unknown feature vector"),
    (lambda d: d.pop("features"), "missing field 'features'"),
    (lambda d: d["lda_coef"][0].__setitem__(0, "x"), "could not convert"),
    (lambda d: d["amplitude"]["1"].update(direction=[1.0, 1.0, 0.0]), "class 1: direction must be a finite unit 3-vector"),
])
def test_bad_model_files_give_clear_errors(tmp_path, day1_fv1_model, edit, message):
    path = corrupt(tmp_path, day1_fv1_model, edit)
    with pytest.raises(BomiError) as info:
        load_model(path)
    assert str(path) in str(info.value) and message in str(info.value)


def test_truncated_and_pickled_files_are_refused(tmp_path, day1_fv1_model, capsys):
    for suffix in (".json", ".npz"):
        path = tmp_path / f"m{suffix}"
        save_model(path, day1_fv1_model)
        path.write_bytes(path.read_bytes()[:100])
        with pytest.raises(BomiError, match="not a valid bomi model"):
            load_model(path)
    pickled = tmp_path / "p.npz"
    np.savez(pickled, meta=np.array([{"format": "bomi-model"}], dtype=object), classes=np.arange(3),
             coef=np.zeros((3, 7)), intercept=np.zeros(3))
    with pytest.raises(BomiError, match="p.npz: not a valid bomi model"):
        load_model(pickled)
    assert main(["evaluate", "--train", str(pickled), "--test", "x.mat", "--png", str(tmp_path / "c.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bomi: error: ") and err.count("\n") == 1 and "p.npz" in err


@pytest.mark.parametrize("seed", range(6))
def test_numerical_rank_is_the_svd_rank_of_the_standardised_features(seed):
    """Against the naive reference (the SVD of the standardised, centred features): windows of
    random rank with duplicated, near-duplicated (1e-9) and scaled columns, as FV3 of a slow signal has."""
    rng = np.random.default_rng(seed)
    rank = int(rng.integers(2, 30))
    x = rng.normal(size=(3000, rank)) @ rng.normal(size=(rank, 40)) * rng.uniform(0.01, 100, 40)
    x[:, 1] = x[:, 0] + 1e-9 * rng.normal(size=3000)
    standardised = (x - x.mean(axis=0)) / x.std(axis=0)
    singular = np.linalg.svd(standardised - standardised.mean(axis=0), compute_uv=False)
    expected = int(np.count_nonzero(singular > RANK_TOLERANCE * singular[0]))
    assert numerical_rank(standardised) == expected


def _former_pipeline(features, labels, shrinkage, priors):
    """The plain scikit-learn Pipeline ``fit_pipeline`` used to fit (the rank from a second
    standardisation of the features, the Pipeline fitting its steps): the independent reference."""
    if shrinkage is None and priors is None:
        steps = [("pca", "passthrough"), ("lda", LinearDiscriminantAnalysis(solver="svd"))]
    else:
        standardised = StandardScaler().fit_transform(features)
        singular = np.linalg.svd(standardised - standardised.mean(axis=0), compute_uv=False)
        rank = int(np.count_nonzero(singular > RANK_TOLERANCE * singular[0]))
        steps = [("pca", PCA(n_components=rank, svd_solver="covariance_eigh")),
                 ("lda", LinearDiscriminantAnalysis(solver="lsqr", shrinkage=shrinkage, priors=priors))]
    with threadpool_limits(limits=1, user_api="blas"):
        return Pipeline([("scale", StandardScaler()), *steps]).fit(features, labels)


@pytest.mark.parametrize("setting", ["copies and shrinkage", "plain"])
def test_fitted_steps_are_the_plain_pipelines_to_the_bit(p1_days, p1_profile, setting):
    """On P1's real day 1 (its profile's turned copies and shrinkage, and the plain LDA), every fitted
    array of every step equals what scikit-learn's own ``Pipeline.fit`` gives."""
    copies = MotionCopies.of(p1_profile) if setting != "plain" else MotionCopies()
    windows, _ = training_windows(p1_days[1], p1_profile.spec, p1_profile.neutral_samples, copies)
    shrinkage = p1_profile.shrinkage if setting != "plain" else None
    priors = recorded_priors(windows.labels, windows.recorded)
    assert (priors is None) == (setting == "plain")
    ours = fit_pipeline(windows.features, windows.labels, shrinkage, priors)
    former = _former_pipeline(windows.features, windows.labels, shrinkage, priors)
    names = {"scale": ("mean_", "scale_", "var_"), "pca": ("mean_", "components_", "explained_variance_"),
             "lda": ("coef_", "intercept_", "classes_", "means_", "priors_")}
    for step, attributes in names.items():
        a, b = ours.named_steps[step], former.named_steps[step]
        if setting == "plain" and step == "pca":
            assert a == b == "passthrough"
            continue
        for name in attributes:
            assert np.array_equal(getattr(a, name), getattr(b, name)), f"{step}.{name}"
    if setting != "plain":
        assert ours.named_steps["pca"].n_components_ < windows.features.shape[1]   # a rank-reducing projection
    test = prepare(p1_days[2], p1_profile.spec, p1_profile.neutral_samples).features
    assert np.array_equal(ours.predict_proba(test), former.predict_proba(test))


def test_pipelines_fitted_together_are_each_the_plain_pipeline_to_the_bit():
    """A cross-validation fold fits every shrinkage at once (``fit_pipelines``: one scaler, one PCA):
    each pipeline is scikit-learn's own ``Pipeline.fit`` of its shrinkage alone, plain LDA included."""
    rng = np.random.default_rng(3)
    labels = np.repeat(np.arange(4), 250)
    features = rng.normal(size=(1000, 12)) + 0.8 * labels[:, None] * rng.normal(size=12)
    features[:, 11] = features[:, 10]                  # a rank the PCA drops
    shrinkages = (None, 1e-3, 0.1, "auto")
    together = fit_pipelines(features, labels, shrinkages)
    for shrinkage, ours in zip(shrinkages, together):
        former = _former_pipeline(features, labels, shrinkage, None)
        assert np.array_equal(ours.predict_proba(features), former.predict_proba(features)), shrinkage
        assert np.array_equal(ours.named_steps["lda"].coef_, former.named_steps["lda"].coef_), shrinkage
    assert together[1].named_steps["pca"] is together[3].named_steps["pca"]   # shared, not refitted
    assert together[1].named_steps["pca"].n_components_ == 11


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_fitting_refuses_non_finite_features_before_any_step(bad):
    """The features are checked once, before the steps (which then skip scikit-learn's own checks)."""
    rng = np.random.default_rng(0)
    features, labels = rng.normal(size=(300, 6)), np.repeat([0, 1, 2], 100)
    features[123, 4] = bad
    for shrinkage in (None, 0.01):
        with pytest.raises(ValueError, match="NaN or infinite"):
            fit_pipeline(features, labels, shrinkage)


def test_a_reset_vote_forgets_every_label():
    """After four F (1) labels a vote of five outputs 1 for a new label 2, twice; reset, it outputs 2 at once
    (what the live loop needs after a break in the stream: no label of the old sitting votes)."""
    vote = MajorityVote(5)
    assert [vote.push(label) for label in (1, 1, 1, 1, 2, 2)] == [1, 1, 1, 1, 1, 1]
    vote.reset()
    assert [vote.push(label) for label in (2, 3)] == [2, 3]
