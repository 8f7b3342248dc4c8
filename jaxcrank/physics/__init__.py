"""The physics: mechanism parameters, contact and friction laws, the closed-form ideal
mechanism and the equations of motion with clearance joints. Imports nothing else of
jaxcrank but [`jaxcrank.errors`][]."""
