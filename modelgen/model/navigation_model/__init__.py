"""Reading the ``navigation:`` section of a model file: an error model derived from the navigation equations.

A model file with a ``navigation:`` section declares no states, noises,
dynamics or measurements of its own: it names the navigation frame, the
mechanization, the error definition, the sensor errors, the measurements as
functions of the navigation state and the approximations, and
:mod:`modelgen.model.perturbation` derives the linear error model.  The
result is an ordinary :class:`~modelgen.model.declaration.ErrorModel`
(dynamics F x + G w, measurements H x), so derivation, code generation and
every check treat it like a hand-written model.  The format is in README.md,
"Navigation equations -> error model".

Every name is generated unless the file gives it: state names
``attitude_error_north``, ``velocity_error_east``, ``position_error_down``,
``latitude_error``; sensor-error states ``gyro_bias_x``; their driving noises
``gyro_bias_driving_noise_x``; parameters of the navigation state
(``latitude``, ``velocity_north``, ``c11`` ...) are declared for the symbols
the derived matrices use.  Bad input is refused with file:line and the names
involved, before anything is derived.

The section is read part by part, one module each:

* :mod:`.section`: the section's keys and vocabulary, the reader with file:line, the declarations collected;
* :mod:`.navigation_state`: the computed navigation state's symbols and the file's own parameters;
* :mod:`.error_states`: the error definition (``errors:``);
* :mod:`.sensor_errors`: sensor-error states and the inertial sensors' white noises;
* :mod:`.measurements`, :mod:`.pseudoranges`, :mod:`.expressions`: the measurements and written equations;
* :mod:`.approximation_entries`: the approximations list;
* :mod:`.derivation`: the whole file to an ErrorModel (:func:`~.derivation.derive_navigation_model`);
* :mod:`.approximation_notes`: the notes and records of what the approximations dropped.
"""
